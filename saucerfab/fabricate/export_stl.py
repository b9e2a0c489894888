"""Binary STL writer (geometry only: STL carries no colour).

Some printer software takes STL for a quick geometry check; the colour goes
in the other formats. Millimetres, file frame of ``scene.json``.
"""

from __future__ import annotations

import numpy as np

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh, generator


def stl_bytes(mesh: TexturedMesh) -> bytes:
    """The binary ``.stl`` file: 80-byte header, count, 50 bytes per triangle."""
    tri = mesh.vertices[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    rec = np.zeros(tri.shape[0], dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"] = n
    rec["v"] = tri
    # the header must not start with "solid" (readers would take it for ASCII STL)
    head = f"binary STL, {generator()}, millimetres".encode("ascii")[:80].ljust(80, b" ")
    return head + np.uint32(tri.shape[0]).tobytes() + rec.tobytes()


def write_stl(mesh: TexturedMesh, options: FabOptions | None = None) -> dict[str, bytes]:
    """``<name>.stl``; no option changes it."""
    return {f"{mesh.name}.stl": stl_bytes(mesh)}
