"""Fabrication: solid, UV atlas and bake, exporters (printer profiles: :mod:`saucerfab.profiles`).

Entry point: :func:`saucerfab.fabricate.pipeline.export_design` (design
folder -> print-ready files + ``scene.json`` + ``export.json``). Modules:

* ``options``     :class:`FabOptions` (base, cup seat, atlas, colours)
* ``solid``       watertight solid with base and cup seat (manifold3d), thin-feature check
* ``atlas``       one-page UV atlas: planar top region + xatlas charts
* ``bake``        texture bake, harmonic fill of unseen areas, page, vertex colours
* ``kernels``     numba kernels of the bake (loaded only when baking)
* ``textured``    :class:`TexturedMesh`, what every writer receives
* ``export_3mf``, ``export_obj``, ``export_glb``, ``export_ply``, ``export_vrml``,
  ``export_stl``   one writer per format, each returning bytes
* ``registry``    the writers of the formats asked for (:mod:`saucerfab.formats`), and the one atomic folder write
* ``scene_json``  ``scene.json`` (schema ``saucerfab.scene/1``)

This package's ``__init__`` stays light (no mesh libraries, no torch): importing
``saucerfab.fabricate.options`` costs nothing.
"""
