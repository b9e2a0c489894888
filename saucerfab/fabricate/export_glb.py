"""Binary glTF 2.0 (GLB) writer: metres, PBR metallic-roughness, embedded PNG.

glTF stores one set of attributes per vertex, so vertices are split where
texture coordinates differ (the UV seams); positions stay bit-identical
across a seam, so merging by position gives back the watertight solid.

Coordinates. The POSITION accessor holds the file frame of ``scene.json``
(z up) in metres, i.e. the same numbers / 1000. glTF's world is +Y up, so
the single node carries the rotation (x, y, z) -> (x, z, -y); viewers then
show the saucer upright, and ``scene.json``'s numbers apply to the mesh's
own (node-local) coordinates. Texture coordinates are flipped to glTF's
(v = 0 at the image's top). The material is non-metallic (metallic 0,
roughness 1) so it does not render dark, and not double-sided (the solid is
closed).
"""

from __future__ import annotations

import json
import struct

import numpy as np

from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh, generator

#: node matrix (column-major, glTF order): z-up file frame -> glTF's y-up world
Z_UP_TO_Y_UP = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]

ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
FLOAT, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5123, 5125
LINEAR, LINEAR_MIPMAP_LINEAR, CLAMP_TO_EDGE = 9729, 9987, 33071


def split_vertices(mesh: TexturedMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One glTF vertex per distinct (position, uv) corner pair.

    Returns:
        positions (K, 3) float64 mm, uvs (K, 2) float64, indices (F, 3) int64.
        Sorted by (position index, uv index), so the output is reproducible.
    """
    t = mesh.uvs.shape[0]
    key = mesh.faces.astype(np.int64) * t + mesh.face_uvs
    uniq, inv = np.unique(key.ravel(), return_inverse=True)
    return mesh.vertices[uniq // t], mesh.uvs[uniq % t], inv.reshape(-1, 3)


def _pad4(b: bytes, fill: bytes = b"\x00") -> bytes:
    return b + fill * ((4 - len(b) % 4) % 4)


def glb_bytes(mesh: TexturedMesh) -> bytes:
    """The ``.glb`` file."""
    pos_mm, uv, idx = split_vertices(mesh)
    pos = (pos_mm / 1000.0).astype(np.float32)
    tex = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1).astype(np.float32)
    small = pos.shape[0] <= 65535
    ind = idx.astype(np.uint16 if small else np.uint32).ravel()

    chunks: list[bytes] = []
    views: list[dict] = []

    def add_view(data: bytes, target: int | None) -> int:
        offset = sum(len(c) for c in chunks)
        view: dict = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        views.append(view)
        chunks.append(_pad4(data))
        return len(views) - 1

    v_ind = add_view(ind.tobytes(), ELEMENT_ARRAY_BUFFER)
    v_pos = add_view(pos.tobytes(), ARRAY_BUFFER)
    v_tex = add_view(tex.tobytes(), ARRAY_BUFFER)
    v_img = add_view(mesh.texture_png, None)
    # float() of a float32 is exact, so min/max equal the stored values bit for bit
    pmin = [float(x) for x in pos.min(axis=0)]
    pmax = [float(x) for x in pos.max(axis=0)]
    doc = {
        "asset": {
            "version": "2.0",
            "generator": generator(),
            "extras": {
                "units": "metres; POSITION = scene.json file coordinates (mm) / 1000, z up",
                "node": "rotates the z-up file frame into glTF's y-up world",
            },
        },
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": mesh.name, "mesh": 0, "matrix": Z_UP_TO_Y_UP}],
        "meshes": [
            {
                "name": mesh.name,
                "primitives": [
                    {"attributes": {"POSITION": 1, "TEXCOORD_0": 2}, "indices": 0, "material": 0, "mode": 4}
                ],
            }
        ],
        "materials": [
            {
                "name": mesh.name,
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": 0, "texCoord": 0},
                    "metallicFactor": 0.0,
                    "roughnessFactor": 1.0,
                },
                "doubleSided": False,
            }
        ],
        "textures": [{"sampler": 0, "source": 0}],
        "images": [{"bufferView": v_img, "mimeType": "image/png"}],
        "samplers": [
            {"magFilter": LINEAR, "minFilter": LINEAR_MIPMAP_LINEAR, "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE}
        ],
        "accessors": [
            {
                "bufferView": v_ind,
                "componentType": UNSIGNED_SHORT if small else UNSIGNED_INT,
                "count": int(ind.shape[0]),
                "type": "SCALAR",
            },
            {
                "bufferView": v_pos,
                "componentType": FLOAT,
                "count": int(pos.shape[0]),
                "type": "VEC3",
                "min": pmin,
                "max": pmax,
            },
            {"bufferView": v_tex, "componentType": FLOAT, "count": int(tex.shape[0]), "type": "VEC2"},
        ],
        "bufferViews": views,
        "buffers": [{"byteLength": sum(len(c) for c in chunks)}],
    }
    js = _pad4(json.dumps(doc, separators=(",", ":")).encode("utf-8"), b" ")
    binary = b"".join(chunks)
    total = 12 + 8 + len(js) + 8 + len(binary)
    return b"".join(
        [
            struct.pack("<4sII", b"glTF", 2, total),
            struct.pack("<I4s", len(js), b"JSON"),
            js,
            struct.pack("<I4s", len(binary), b"BIN\x00"),
            binary,
        ]
    )


def write_glb(mesh: TexturedMesh, options: FabOptions | None = None) -> dict[str, bytes]:
    """``<name>.glb``; no option changes it."""
    return {f"{mesh.name}.glb": glb_bytes(mesh)}
