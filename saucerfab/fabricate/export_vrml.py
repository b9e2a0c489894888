"""VRML 2.0 (VRML97) writer: an IndexedFaceSet with an ImageTexture beside it.

Stratasys colour workflows (GrabCAD Print, older PolyJet colour software)
and many bureaus take VRML with its texture as a separate file. Coordinates
are shared (``coordIndex``) and texture coordinates indexed apart
(``texCoordIndex``), so the mesh is watertight as written. Units are
millimetres in the file frame of ``scene.json`` (VRML nominally means metres;
printer software asks for the unit on import, which is why the header says
so). Texture coordinates have (0, 0) at the image's bottom left, as
saucerfab's do.
"""

from __future__ import annotations

import numpy as np

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh, fmt_rows, generator

UV_DECIMALS = 7


def wrl_text(mesh: TexturedMesh) -> str:
    """The ``.wrl`` file."""
    out = [
        "#VRML V2.0 utf8\n",
        f"# {generator()}\n",
        f"# units: millimetres (file frame of scene.json); texture: {mesh.texture_name}\n",
        f'WorldInfo {{ title "{mesh.name}" info [ "units: millimetres" ] }}\n',
        f"DEF {mesh.name} Shape {{\n",
        "  appearance Appearance {\n",
        "    material Material { diffuseColor 1 1 1 specularColor 0 0 0 }\n",
        f'    texture ImageTexture {{ url [ "{mesh.texture_name}" ] repeatS FALSE repeatT FALSE }}\n',
        "  }\n",
        "  geometry IndexedFaceSet {\n",
        "    solid TRUE\n    ccw TRUE\n    convex TRUE\n    creaseAngle 0\n",
        "    coord Coordinate { point [\n",
    ]
    out.extend(fmt_rows(mesh.vertices, mesh.decimals, template="      {} {} {},\n"))
    out.append("    ] }\n    texCoord TextureCoordinate { point [\n")
    out.extend(fmt_rows(mesh.uvs, UV_DECIMALS, template="      {} {},\n"))
    out.append("    ] }\n    coordIndex [\n")
    out.extend("      {} {} {} -1,\n".format(*r) for r in np.asarray(mesh.faces).tolist())
    out.append("    ]\n    texCoordIndex [\n")
    out.extend("      {} {} {} -1,\n".format(*r) for r in np.asarray(mesh.face_uvs).tolist())
    out.append("    ]\n  }\n}\n")
    return "".join(out)


def write_vrml(mesh: TexturedMesh, options: FabOptions | None = None) -> dict[str, bytes]:
    """``<name>.wrl`` and its texture ``<name>.png``; no option changes them."""
    return {f"{mesh.name}.wrl": wrl_text(mesh).encode(), mesh.texture_name: mesh.texture_png}
