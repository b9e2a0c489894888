"""PLY writer: binary little endian, per-vertex sRGB colour.

PLY carries colour per vertex, not a texture: each vertex gets the atlas
colour around it (:func:`saucerfab.fabricate.bake.vertex_colors`), so detail
finer than the saucer's grid is lost - send 3MF, OBJ or VRML where the
printer takes them. Positions are shared (watertight as written), float32 in
millimetres in the file frame of ``scene.json``.
"""

from __future__ import annotations

import numpy as np

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh, generator


def ply_bytes(mesh: TexturedMesh) -> bytes:
    """The ``.ply`` file."""
    v, f = mesh.vertices, mesh.faces
    header = (
        "ply\n"
        "format binary_little_endian 1.0\n"
        f"comment {generator()}\n"
        "comment units: millimetres (file frame of scene.json); colours sRGB\n"
        f"element vertex {v.shape[0]}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        f"element face {f.shape[0]}\n"
        "property list uchar int vertex_indices\n"
        "end_header\n"
    ).encode("ascii")
    vert = np.empty(v.shape[0], dtype=[("p", "<f4", 3), ("c", "u1", 3)])
    vert["p"] = v
    vert["c"] = mesh.vertex_rgb
    face = np.empty(f.shape[0], dtype=[("n", "u1"), ("i", "<i4", 3)])
    face["n"] = 3
    face["i"] = f
    return header + vert.tobytes() + face.tobytes()


def write_ply(mesh: TexturedMesh, options: FabOptions | None = None) -> dict[str, bytes]:
    """``<name>.ply``; no option changes it."""
    return {f"{mesh.name}.ply": ply_bytes(mesh)}
