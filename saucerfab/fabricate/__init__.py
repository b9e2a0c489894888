"""Fabrication: solid, UV atlas and bake, exporters (printer profiles: :mod:`saucerfab.model.profiles`).

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
* ``registry``    the writers of the formats asked for (:mod:`saucerfab.files.formats`), and the one atomic folder write
* ``scene_json``  ``scene.json`` written (schema ``saucerfab.scene/1``)
* ``scene_file``  ``scene.json`` read back, bounded and checked: the one reader and type (verify, the 3D view)
* ``sides``       the surfaces around the top painted in the backgrounds the eye sees there
* ``seat``        the cup seat's 2-D rules

This package's ``__init__`` stays light (no mesh libraries, no torch): importing
``saucerfab.fabricate.options`` costs nothing.
"""
