"""Hard rasterization: brute-force ray casting agreement, textures, conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from render_reference import rasterize_hard_reference

from saucerfab.errors import ConfigError
from saucerfab.model.heightfield import base_shape, make_grid, triangulate
from saucerfab.model.scene import Saucer, Scene
from saucerfab.render import Camera, rasterize_hard, render_face_colors_hard, render_textured

TAN = 0.2


def ndc_camera(size: int) -> Camera:
    return Camera((0.0, -5.0, 0.0), (0.0, 0.0, 0.0), math.degrees(math.atan(TAN)), size)


def world_from_ndc(ndc: np.ndarray, depth: np.ndarray) -> np.ndarray:
    s = depth * TAN
    return np.stack([ndc[..., 0] * s, depth - 5.0, ndc[..., 1] * s], axis=-1)


def overlapping_triangles(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Big random triangles that overlap, tilt in depth and cross the image border."""
    rng = np.random.default_rng(seed)
    ndc = rng.uniform(-1.3, 1.3, (n, 3, 2))
    depth = rng.uniform(4.5, 6.0, (n, 3))
    return world_from_ndc(ndc, depth).reshape(-1, 3), np.arange(3 * n).reshape(n, 3)


def saucer_mesh(n: int = 14) -> tuple[np.ndarray, np.ndarray]:
    grid = make_grid(Saucer(resolution=n))
    return grid.vertices(base_shape("waves", n)), triangulate(n)


def _compare(v: np.ndarray, f: np.ndarray, cam: Camera) -> None:
    fid, bary, depth = rasterize_hard(v, f, cam)
    rf, rb, rd, margin = rasterize_hard_reference(v, f, cam)
    clear = margin > 1e-7  # pixels on an edge go either way with rounding
    assert clear.mean() > 0.9
    np.testing.assert_array_equal(fid[clear], rf[clear])
    hit = clear & (rf >= 0)
    assert hit.sum() > 20
    np.testing.assert_allclose(depth[hit], rd[hit], rtol=1e-10)
    np.testing.assert_allclose(bary[hit], rb[hit], atol=1e-9)
    assert np.all(np.isinf(depth[fid < 0])) and np.all(bary[fid < 0] == 0)


@pytest.mark.parametrize("seed", [0, 1])
def test_matches_ray_casting_with_occlusion(seed: int) -> None:
    v, f = overlapping_triangles(6, seed)
    _compare(v, f, ndc_camera(40))


def test_matches_ray_casting_on_the_paper_saucer() -> None:
    v, f = saucer_mesh()
    cam = Camera.from_scene(Scene(), "direct").with_size(48)
    _compare(v, f, cam)
    # the mirrored saucer (flipped winding) is drawn as well
    mirrored = v * np.array([1.0, -1.0, 1.0]) + np.array([0.0, -0.8, 0.0])
    _compare(mirrored, f, Camera.from_scene(Scene(), "reflected").with_size(48))


def test_closed_grid_has_no_cracks_and_takes_torch() -> None:
    v, f = saucer_mesh(20)
    cam = Camera.from_scene(Scene(), "direct").with_size(96)
    fid, _, _ = rasterize_hard(torch.as_tensor(v), torch.as_tensor(f), cam)
    # every pixel between the first and last covered column of a covered row is covered
    rows = np.nonzero((fid >= 0).any(axis=1))[0]
    assert rows.size > 10
    for i in rows[1:-1]:
        cols = np.nonzero(fid[i] >= 0)[0]
        assert cols.size == cols[-1] - cols[0] + 1


def test_image_size_override_and_thread_independence() -> None:
    import numba

    v, f = overlapping_triangles(12, 3)
    a = rasterize_hard(v, f, ndc_camera(16), image_size=57)
    assert a[0].shape == (57, 57)
    old = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        b = rasterize_hard(v, f, ndc_camera(57))
    finally:
        numba.set_num_threads(old)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


def test_face_colors_and_background() -> None:
    v, f = overlapping_triangles(5, 4)
    colors = np.random.default_rng(0).random((5, 3))
    cam = ndc_camera(32)
    img = render_face_colors_hard(v, f, colors, cam, background=(0.1, 0.2, 0.3))
    fid, _, _ = rasterize_hard(v, f, cam)
    np.testing.assert_array_equal(img[fid >= 0], colors[fid[fid >= 0]])
    np.testing.assert_array_equal(img[fid < 0], np.tile([0.1, 0.2, 0.3], ((fid < 0).sum(), 1)))


def _ramp_texture(h: int, w: int) -> np.ndarray:
    """Texel (r, c) holds its own (u, v) centre and 0.25: bilinear lookups return (u, v, 0.25)."""
    u = (np.arange(w) + 0.5) / w
    v = 1 - (np.arange(h) + 0.5) / h
    return np.stack([np.broadcast_to(u, (h, w)), np.broadcast_to(v[:, None], (h, w)), np.full((h, w), 0.25)], -1)


def test_textured_is_perspective_correct() -> None:
    """A quad tilted in depth, UVs (0,0) bottom-left .. (1,1) top-right: the rendered
    (R, G) is the UV of the point the pixel's ray hits."""
    ndc = np.array([[-0.8, -0.7], [0.7, -0.8], [0.8, 0.75], [-0.75, 0.8]])
    depth = np.array([4.2, 4.6, 6.5, 6.0])  # strongly tilted: affine UVs would be far off
    v = world_from_ndc(ndc, depth)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    face_uvs = uv[f]
    cam = ndc_camera(48)
    img = render_textured(v, f, face_uvs, _ramp_texture(64, 64), cam, background=(1.0, 0.0, 1.0))
    rf, rb, _, margin = rasterize_hard_reference(v, f, cam)
    inside = (rf >= 0) & (margin > 1e-7)
    expect = np.einsum("nk,nkc->nc", rb[inside], face_uvs[rf[inside]])
    # bilinear on the ramp is exact away from the outermost half texel
    interior = np.all((expect > 0.5 / 64) & (expect < 1 - 0.5 / 64), axis=1)
    assert interior.sum() > 500
    np.testing.assert_allclose(img[inside][interior, :2], expect[interior], atol=1e-9)
    np.testing.assert_allclose(img[inside][:, 2], 0.25)
    np.testing.assert_array_equal(img[rf < 0], np.tile([1.0, 0.0, 1.0], ((rf < 0).sum(), 1)))
    # orientation: the texture's top row (v = 1) appears at the top of the quad
    assert img[6, 24, 1] > 0.9 and img[41, 24, 1] < 0.1
    assert img[24, 6, 0] < 0.1 and img[24, 41, 0] > 0.9


def test_textured_uint8_matches_float() -> None:
    ndc = np.array([[-0.9, -0.9], [0.9, -0.9], [0.9, 0.9], [-0.9, 0.9]])
    v = world_from_ndc(ndc, np.full(4, 5.0))
    f = np.array([[0, 1, 2], [0, 2, 3]])
    face_uvs = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])[f]
    tex8 = np.random.default_rng(1).integers(0, 256, (9, 7, 3), dtype=np.uint8)
    a = render_textured(v, f, face_uvs, tex8, ndc_camera(24))
    b = render_textured(v, f, torch.as_tensor(face_uvs), tex8.astype(np.float64) / 255, ndc_camera(24))
    np.testing.assert_allclose(a, b, atol=1e-12)
    assert a.min() >= 0 and a.max() <= 1


V3, F1 = np.zeros((3, 3)), np.array([[0, 1, 2]])


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda cam: rasterize_hard(np.zeros((3, 2)), F1, cam), "vertices"),
        (lambda cam: rasterize_hard(V3, np.array([[0, 1, 3]]), cam), "index"),
        (lambda cam: rasterize_hard(V3, F1, cam, image_size=0), "image_size"),
        (lambda cam: render_face_colors_hard(V3, F1, np.zeros((2, 3)), cam), "face_colors"),
        (lambda cam: render_textured(V3, F1, np.zeros((1, 3)), np.zeros((2, 2, 3)), cam), "face_uvs"),
        (lambda cam: render_textured(V3, F1, np.zeros((1, 3, 2)), np.zeros((2, 2)), cam), "texture"),
    ],
)
def test_bad_arguments(call, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ConfigError, match=match):
        call(ndc_camera(8))
