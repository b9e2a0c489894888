"""The texels under 2-D triangles: the row-span raster against the box-by-box reference."""

from __future__ import annotations

import numpy as np
import pytest

from saucerfab.render import texels
from saucerfab.render.texels import raster_triangles_2d, raster_triangles_2d_reference


def _triangles(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    big = rng.uniform(-10, 74, (40, 3, 2))  # reaching off the image
    small = rng.uniform(0, 4, (300, 3, 2)) + rng.uniform(0, 60, (300, 1, 2))
    thin = np.stack([rng.uniform(0, 64, (60, 2)), rng.uniform(0, 64, (60, 2)), np.zeros((60, 2))], 1)
    thin[:, 2] = thin[:, 0] + 0.3  # long, thin, diagonal: a box far larger than the triangle
    flat = rng.uniform(0, 64, (20, 3, 2))
    flat[:, :, 1] = 17.5  # degenerate: on a texel row's centre line
    grid = np.array([[[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]], [[4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]])  # shared edge
    return np.concatenate([big, small, thin, flat, grid])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_row_span_raster_equals_the_reference(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    tri = _triangles(seed)
    want = raster_triangles_2d_reference(tri, 64, 48)
    for chunk, budget in ((4096, texels.CHUNK_TEXELS), (7, texels.CHUNK_TEXELS), (4096, 500)):
        monkeypatch.setattr(texels, "CHUNK_TEXELS", budget)
        got = raster_triangles_2d(tri, 64, 48, chunk=chunk)
        for g, w in zip(got, want):
            assert np.array_equal(g, w)


def test_a_right_triangle_covers_the_texel_centres_under_it() -> None:
    tri = np.array([[[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]])
    pix, ti, bary = raster_triangles_2d(tri, 8, 8)
    assert {(p % 8, p // 8) for p in pix} == {(x, y) for x in range(8) for y in range(8) if x + y + 1 <= 4}
    assert (ti == 0).all() and np.allclose(bary.sum(axis=1), 1.0)


def test_no_triangles() -> None:
    pix, ti, bary = raster_triangles_2d(np.zeros((0, 3, 2)), 8, 8)
    assert pix.shape == (0,) and ti.shape == (0,) and bary.shape == (0, 3)
