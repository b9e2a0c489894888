"""The tiling of the numba backend against plain references: boxes and bins, array for array."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from saucerfab.render.soft_tiles import TILE_H, TILE_W, _bin_faces, _face_boxes
from saucerfab.render.soft_torch import face_pixel_boxes


def bin_faces_reference(box: np.ndarray, n_ty: int, n_tx: int) -> tuple[np.ndarray, ...]:
    """:func:`_bin_faces` written out face after face, entry after entry."""
    entries = []  # (face, tile, rows in the tile), numbered face by face
    face_start = [0]
    for r0, r1, c0, c1 in box.tolist():
        if r1 >= r0 and c1 >= c0:
            for ty in range(r0 // TILE_H, r1 // TILE_H + 1):
                rows = min(r1, ty * TILE_H + TILE_H - 1) - max(r0, ty * TILE_H) + 1
                for tx in range(c0 // TILE_W, c1 // TILE_W + 1):
                    entries.append((len(face_start) - 1, ty * n_tx + tx, rows))
        face_start.append(len(entries))
    tile_entry = sorted(range(len(entries)), key=lambda e: (entries[e][1], e))
    count = np.bincount([t for _, t, _ in entries], minlength=n_ty * n_tx)
    return (
        np.concatenate([[0], np.cumsum(count)]),
        np.array(tile_entry, np.int64),
        np.array([f for f, _, _ in entries], np.int64),
        np.array(face_start, np.int64),
        np.concatenate([[0], np.cumsum([r for _, _, r in entries])]).astype(np.int64),
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bin_faces_matches_the_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    size, n = 100, 400
    r0 = rng.integers(0, size, n)
    c0 = rng.integers(0, size, n)
    # boxes of 1 to 40 pixels, cut by the image, some empty (row1 < row0 or col1 < col0)
    box = np.stack([r0, r0 + rng.integers(-2, 40, n), c0, c0 + rng.integers(-2, 40, n)], 1)
    box[:, 1::2] = np.minimum(box[:, 1::2], size - 1)
    box = box.astype(np.int32)
    box[::7, 1] = box[::7, 0] - 1
    n_ty, n_tx = -(-size // TILE_H), -(-size // TILE_W)
    got = _bin_faces(box, n_ty, n_tx)
    want = bin_faces_reference(box, n_ty, n_tx)
    for name, g, w in zip(("tile_start", "tile_entry", "entry_face", "face_start", "row_start"), got, want):
        np.testing.assert_array_equal(g, w, err_msg=name)


def test_face_boxes_match_the_torch_backend() -> None:
    rng = np.random.default_rng(3)
    size, n = 64, 500
    cxy = rng.uniform(-1.3, 1.3, (n, 6))
    cxy[5, 2] = np.nan  # no pixels for a face with a non-finite corner
    cxy[9] = 1e30  # far off: clamped before rounding
    radius = 0.02
    got = _face_boxes(cxy, radius, size)
    want = np.stack([w.numpy() for w in face_pixel_boxes(torch.as_tensor(cxy.reshape(n, 3, 2)), size, radius)], 1)
    empty = lambda b: (b[:, 1] < b[:, 0]) | (b[:, 3] < b[:, 2])  # noqa: E731
    np.testing.assert_array_equal(empty(got), empty(want))
    assert empty(got)[5] and empty(got)[9]
    np.testing.assert_array_equal(got[~empty(got)], want[~empty(want)])
