"""Wavefront OBJ + MTL + PNG writer (optionally one zip, the form bureaus ask for).

Positions are written once each (``v``) and texture coordinates separately
(``vt``), faces as ``f v/vt ...``: the mesh is watertight as written, with UV
seams only in the ``vt`` indices. The material is white (``Kd 1 1 1``) so the
texture (``map_Kd``) is shown and printed unmodulated; ``vt`` uses OBJ's
convention (v = 0 at the image's bottom), which is saucerfab's. Units are
millimetres, in the file frame of ``scene.json``.
"""

from __future__ import annotations

import numpy as np

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh, deterministic_zip, fmt_rows, generator

UV_DECIMALS = 7


def mtl_text(mesh: TexturedMesh) -> str:
    """The ``.mtl`` file: one white, non-specular material with the atlas as ``map_Kd``."""
    return (
        f"# {generator()}\n"
        f"newmtl {mesh.name}\n"
        "Ka 1 1 1\n"
        "Kd 1 1 1\n"
        "Ks 0 0 0\n"
        "Ns 1\n"
        "d 1\n"
        "illum 1\n"
        f"map_Kd {mesh.texture_name}\n"
    )


def obj_text(mesh: TexturedMesh) -> str:
    """The ``.obj`` file (1-based indices)."""
    lines = [
        f"# {generator()}\n",
        "# units: millimetres (file frame of scene.json); watertight: shared v, separate vt\n",
        f"# vertices {mesh.vertices.shape[0]} faces {mesh.faces.shape[0]}\n",
        f"mtllib {mesh.name}.mtl\n",
        f"o {mesh.name}\n",
    ]
    lines.extend(fmt_rows(mesh.vertices, mesh.decimals, template="v {} {} {}\n"))
    lines.extend(fmt_rows(mesh.uvs, UV_DECIMALS, template="vt {} {}\n"))
    lines.append(f"usemtl {mesh.name}\ns off\n")
    idx = np.empty((mesh.faces.shape[0], 6), np.int64)
    idx[:, 0::2] = mesh.faces + 1
    idx[:, 1::2] = mesh.face_uvs + 1
    lines.extend("f {}/{} {}/{} {}/{}\n".format(*r) for r in idx.tolist())
    return "".join(lines)


def write_obj(mesh: TexturedMesh, options: FabOptions | None = None) -> dict[str, bytes]:
    """``<name>.obj``, ``<name>.mtl`` and ``<name>.png``; or all three in ``<name>.zip`` (``options.obj_zip``)."""
    files = {
        f"{mesh.name}.obj": obj_text(mesh).encode(),
        f"{mesh.name}.mtl": mtl_text(mesh).encode(),
        mesh.texture_name: mesh.texture_png,
    }
    if options is None or not options.obj_zip:
        return files
    entries = [(k, v, not k.endswith(".png")) for k, v in files.items()]
    return {f"{mesh.name}.zip": deterministic_zip(entries)}
