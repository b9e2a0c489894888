"""glTF instancing: a run of one mesh's instances is added in one batch; the result is as if one by one."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import fixtures_check as fx
import numpy as np
from test_check_budgets import glb_with

from saucerfab.check import check_mesh
from saucerfab.check.limits import DEFAULT_LIMITS
from saucerfab.check.readers import read_mesh


def _trs(node: dict[str, Any]) -> np.ndarray:
    """A node's local matrix, the plain way (the reference for the reader's)."""
    M = np.eye(4)
    if "matrix" in node:
        return np.array(node["matrix"], float).reshape(4, 4).T
    x, y, z, w = node.get("rotation", [0, 0, 0, 1])
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    M[:3, :3] = R * np.array(node.get("scale", [1, 1, 1]), float)
    M[:3, 3] = node.get("translation", [0, 0, 0])
    return M


def test_batched_instances_equal_one_by_one(tmp_path: Path) -> None:
    V, F = fx.box()
    uv = fx.box_uv(V)
    s = np.sqrt(0.5)
    nodes: list[dict[str, Any]] = [
        {"mesh": 0, "translation": [0.1, 0, 0]},
        {"mesh": 0, "scale": [-1, 1, 1]},  # mirrored: corners reversed to stay outward
        {"mesh": 1, "rotation": [0, 0, s, s]},
        {"mesh": 0, "matrix": [1, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1, 0, 0.3, 0, 0, 1]},
        {"mesh": 0},
        {"mesh": 1, "translation": [0, 0.2, 0]},
        {"mesh": 1, "translation": [0, 0.4, 0], "scale": [1, 1, -1]},
    ]

    def edit(doc: dict[str, Any]) -> None:
        textured = doc["meshes"][0]["primitives"][0]
        plain = {"attributes": {"POSITION": 0}, "indices": 1}
        doc["meshes"] = [{"primitives": [textured]}, {"primitives": [textured, plain]}]
        doc["nodes"] = [{"children": list(range(1, len(nodes) + 1))}, *nodes]

    base = fx.write_glb(tmp_path / "base.glb", V, F, uv=uv, texture=fx.png_bytes())
    p = glb_with(tmp_path / "inst.glb", edit, src=base)
    md = read_mesh(p, DEFAULT_LIMITS)

    V32 = (V * 0.001).astype("<f4").astype(float)
    mesh_prims = {0: [True], 1: [True, False]}  # textured or not, per primitive
    exp_v, exp_f, exp_uv, exp_tex = [], [], [], []
    nv = 0
    for node in nodes:
        M = _trs(node)
        flip = np.linalg.det(M[:3, :3]) < 0
        for textured in mesh_prims[node["mesh"]]:
            exp_v.append(V32 @ M[:3, :3].T + M[:3, 3])
            f = F[:, ::-1] if flip else F
            exp_f.append(f + nv)
            exp_uv.append(uv.astype("<f4").astype(float)[f] if textured else np.full((len(F), 3, 2), np.nan))
            exp_tex.append(np.full(len(F), 0 if textured else -1))
            nv += len(V)
    assert md.parts == sum(len(mesh_prims[n["mesh"]]) for n in nodes)
    assert np.allclose(md.vertices, np.concatenate(exp_v), rtol=0, atol=1e-12)
    assert np.array_equal(md.faces, np.concatenate(exp_f))
    assert md.corner_uv is not None and md.face_texture is not None
    assert np.allclose(md.corner_uv, np.concatenate(exp_uv), equal_nan=True)
    assert np.array_equal(md.face_texture, np.concatenate(exp_tex))
    r = check_mesh(p)
    assert "internal_error" not in r.codes and "inverted_normals" not in r.codes, r.reason()

