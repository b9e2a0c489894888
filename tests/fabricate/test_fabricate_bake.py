"""Tests of saucerfab.fabricate.atlas and .bake: layout, UVs, the bake kernel, harmonic fill."""

from __future__ import annotations

import io
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from saucerfab.fabricate.atlas import build_uvmap, layout_page, surface_density, top_uv
from saucerfab.fabricate.bake import (
    bake_page,
    bake_top,
    bake_top_reference,
    compose_page,
    harmonic_fill,
    harmonic_fill_reference,
    locate_columns,
    locate_rows,
    png_bytes,
    sample_bilinear,
    vertex_colors,
)
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.solid import build_solid
from saucerfab.model.design import Design, FaceView
from saucerfab.model.design_folder import synthetic_design


def random_design(n: int = 6, tex: int = 16, seed: int = 0) -> Design:
    """Random heights, face uvs, views and texture: nothing lines up by accident."""
    rng = np.random.default_rng(seed)
    d = synthetic_design(resolution=n, texture_size=tex, seed=seed)
    f = d.face_uvs.shape[0]
    return replace(
        d,
        heights=d.heights + rng.uniform(0, 0.1, d.heights.shape),
        face_uvs=rng.uniform(0, 1, (f, 3, 2)).astype(np.float32),
        face_view=rng.integers(0, 4, f).astype(np.uint8),
        texture=rng.integers(0, 256, (tex, tex, 3)).astype(np.uint8),
    )


def grid_of(d: Design, s: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    (x0, x1), (y0, y1) = d.scene.saucer.x_range, d.scene.saucer.y_range
    return np.linspace(x0, x1, d.n) * s, np.linspace(y0, y1, d.n) * s, d.heights * s


# --------------------------------------------------------------------------- atlas


def test_layout_regions_are_disjoint_padded_and_inside_the_page() -> None:
    d = synthetic_design(resolution=20, texture_size=32)
    xs, ys, h = grid_of(d)
    lay = layout_page(512, 8, xs, ys, h)
    t, c = lay.top, lay.charts
    for r in (t, c):
        assert r.x >= 8 and r.y >= 8 and r.x + r.w <= 512 - 8 and r.y + r.h <= 512 - 8
    assert t.x + t.w + 16 <= c.x  # two gutters between the regions
    assert (np.diff(lay.col_px) > 0).all() and (np.diff(lay.row_px) < 0).all()
    assert lay.col_px[[0, -1]].tolist() == [t.x, t.x + t.w]
    assert lay.row_px[[0, -1]].tolist() == [t.y + t.h, t.y]


def test_steep_rows_get_more_texels() -> None:
    """A sawtooth: the steep faces' rows of cells get texels in proportion to their surface length."""
    n = 13
    xs = np.linspace(0, 120, n)
    ys = np.linspace(0, 120, n)
    h = np.tile((np.arange(n) % 3 * 10.0)[:, None], (1, n))  # rise 10, rise 10, drop 20 per 10 mm
    dx, dy = surface_density(h, xs, ys)
    assert np.allclose(dx, 1.0)
    lay = layout_page(1024, 8, xs, ys, h)
    rows = -np.diff(lay.row_px)
    assert np.allclose(rows / rows.sum(), dy / dy.sum())
    assert rows.max() / rows.min() == pytest.approx(dy.max() / dy.min())
    assert dy.max() == pytest.approx(np.sqrt(5.0)) and dy.min() == pytest.approx(np.sqrt(2.0))


def test_top_uv_of_grid_vertices_hits_the_breakpoints() -> None:
    d = synthetic_design(resolution=9, texture_size=32)
    xs, ys, h = grid_of(d)
    lay = layout_page(256, 4, xs, ys, h)
    gx, gy = np.meshgrid(xs, ys)
    uv = top_uv(lay, xs, ys, np.stack([gx.ravel(), gy.ravel()], 1)).reshape(9, 9, 2)
    assert np.allclose(uv[0, :, 0] * 256, lay.col_px)
    assert np.allclose((1 - uv[:, 0, 1]) * 256, lay.row_px)


def test_uvmap_covers_every_corner_inside_its_region() -> None:
    d = synthetic_design(resolution=12, texture_size=32)
    solid = build_solid(d, d.scene.mm_per_unit, FabOptions())
    lay = layout_page(256, 8, solid.grid_x, solid.grid_y, solid.heights)
    uvm = build_uvmap(solid, lay)
    assert uvm.face_uvs.shape == solid.faces.shape
    assert uvm.face_uvs.min() >= 0 and uvm.face_uvs.max() < uvm.uvs.shape[0]
    px = uvm.uvs[:, 0] * 256
    py = (1 - uvm.uvs[:, 1]) * 256

    def inside(idx: np.ndarray, r: object) -> bool:
        return bool(
            (px[idx] >= r.x - 1e-9).all() and (px[idx] <= r.x + r.w + 1e-9).all()  # type: ignore[attr-defined]
            and (py[idx] >= r.y - 1e-9).all() and (py[idx] <= r.y + r.h + 1e-9).all()  # type: ignore[attr-defined]
        )

    assert inside(np.unique(uvm.face_uvs[solid.is_top]), lay.top)
    assert inside(np.unique(uvm.face_uvs[~solid.is_top]), lay.charts)
    # top corners of one position share one uv (a continuous map); chart triangles are not degenerate
    t = uvm.uvs[uvm.face_uvs[~solid.is_top]]
    area = 0.5 * np.abs((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (t[:, 2, 0] - t[:, 0, 0]) * (t[:, 1, 1] - t[:, 0, 1]))
    assert (area > 0).all()
    pos_uv = {}
    for f, fu in zip(solid.faces[solid.is_top].ravel(), uvm.face_uvs[solid.is_top].ravel()):
        assert pos_uv.setdefault(int(f), int(fu)) == int(fu)


# --------------------------------------------------------------------------- bake


def test_locate_inverts_the_breakpoints() -> None:
    d = random_design(7)
    xs, ys, h = grid_of(d)
    lay = layout_page(128, 4, xs, ys, h)
    j, fx = locate_columns(lay)
    px = lay.top.x + np.arange(lay.top.w) + 0.5
    assert np.allclose(lay.col_px[j] + fx * (lay.col_px[j + 1] - lay.col_px[j]), px)
    i, fy = locate_rows(lay)
    py = lay.top.y + np.arange(lay.top.h) + 0.5
    assert np.allclose(lay.row_px[i] + fy * (lay.row_px[i + 1] - lay.row_px[i]), py)
    assert ((fx >= 0) & (fx <= 1)).all() and ((fy >= 0) & (fy <= 1)).all()


def test_bake_kernel_matches_the_slow_reference() -> None:
    d = random_design(6, tex=16, seed=3)
    xs, ys, h = grid_of(d)
    lay = layout_page(64, 2, xs, ys, h)
    rgb, known = bake_top(d, lay)
    ref_rgb, ref_known, ref_face = bake_top_reference(d, lay)
    assert (ref_face >= 0).all(), "a texel centre outside every face"
    # texels on a shared edge may go to either face; those are rare (measure zero)
    j, fx = locate_columns(lay)
    i, fy = locate_rows(lay)
    face = 2 * (i[:, None] * 5 + j[None, :]) + (fy[:, None] > fx[None, :])
    same = face == ref_face
    assert same.mean() > 0.99
    np.testing.assert_allclose(rgb[same], ref_rgb[same], atol=1e-3)
    np.testing.assert_array_equal(known[same], ref_known[same])


def test_sample_bilinear_convention() -> None:
    img = np.zeros((2, 2, 3), np.uint8)
    img[0, 0] = 255  # top-left texel
    # u left->right, v bottom->top: the top-left texel centre is (0.25, 0.75)
    assert sample_bilinear(img, np.array([[0.25, 0.75]]))[0, 0] == 255
    assert sample_bilinear(img, np.array([[0.25, 0.25]]))[0, 0] == 0
    assert sample_bilinear(img, np.array([[0.5, 0.75]]))[0, 0] == pytest.approx(127.5)


def test_harmonic_fill_reference_reproduces_a_discrete_harmonic_function() -> None:
    # x^2 - y^2 has a zero 5-point Laplacian; with the border known the solution is exact
    y, x = np.mgrid[0:20, 0:24].astype(np.float64)
    f = (x - 10) ** 2 - (y - 8) ** 2
    known = np.zeros(f.shape, bool)
    known[0, :] = known[-1, :] = known[:, 0] = known[:, -1] = True
    known[5:8, 9:12] = True
    out = harmonic_fill_reference(f[..., None], known)
    np.testing.assert_allclose(out[..., 0], f, atol=1e-3)


def blob_mask(size: int, frac: float, seed: int) -> np.ndarray:
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    noise = ndimage.gaussian_filter(rng.normal(size=(size, size)), size / 16)
    return noise <= np.quantile(noise, 1 - frac)  # True = known


@pytest.mark.parametrize("size, frac", [(97, 0.3), (200, 0.5)])
def test_harmonic_fill_matches_the_direct_solve(size: int, frac: float) -> None:
    from scipy import ndimage

    rng = np.random.default_rng(size)
    # an image-like texture: smooth areas with texel-scale detail on top
    vals = ndimage.gaussian_filter(rng.uniform(0, 255, (size, size, 3)), (3, 3, 0)).astype(np.float32)
    known = blob_mask(size, frac, size)
    known[size // 2, :] = True  # a thin known line across the unknown blobs
    fast = harmonic_fill(vals, known)
    ref = harmonic_fill_reference(vals, known)
    np.testing.assert_array_equal(fast[known], vals[known])  # known texels untouched
    err = np.abs(fast - ref)[~known]
    assert err.max() < 1.0 and err.mean() < 0.2, (err.max(), err.mean())  # of 255
    # maximum principle
    assert fast.min() >= vals[known].min() - 1e-3 and fast.max() <= vals[known].max() + 1e-3


def test_harmonic_fill_converges_on_white_noise() -> None:
    """The hardest boundary data: every texel independent. More cycles, less error."""
    rng = np.random.default_rng(7)
    vals = rng.uniform(0, 255, (160, 160, 3)).astype(np.float32)
    known = blob_mask(160, 0.5, 7)
    ref = harmonic_fill_reference(vals, known)
    errs = [float(np.abs(harmonic_fill(vals, known, cycles=c) - ref)[~known].mean()) for c in (0, 2, 6)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[1] < 2.5 and errs[2] < 0.5, errs


def test_harmonic_fill_edge_cases() -> None:
    v = np.full((8, 8, 3), 7.0, np.float32)
    np.testing.assert_array_equal(harmonic_fill(v, np.ones((8, 8), bool)), v)
    np.testing.assert_array_equal(harmonic_fill(v, np.zeros((8, 8), bool)), v)
    known = np.zeros((8, 8), bool)
    known[0, 0] = True
    out = harmonic_fill(v * 0 + np.float32(3.0), known)
    assert np.allclose(out, 3.0)  # one known texel: a constant continuation


def test_compose_page_dilates_the_top_into_its_gutter() -> None:
    d = synthetic_design(resolution=8, texture_size=32)
    xs, ys, h = grid_of(d)
    lay = layout_page(128, 6, xs, ys, h)
    top = np.random.default_rng(0).integers(0, 256, (lay.top.h, lay.top.w, 3)).astype(np.uint8)
    page = compose_page(lay, top, (10, 20, 30))
    t = lay.top
    np.testing.assert_array_equal(page[t.y : t.y + t.h, t.x : t.x + t.w], top)
    np.testing.assert_array_equal(page[t.y - 6 : t.y, t.x : t.x + t.w], np.repeat(top[:1], 6, axis=0))
    np.testing.assert_array_equal(page[t.y : t.y + t.h, t.x + t.w : t.x + t.w + 6], np.repeat(top[:, -1:], 6, axis=1))
    np.testing.assert_array_equal(page[t.y - 6, t.x - 6], top[0, 0])  # corners too
    c = lay.charts
    assert (page[c.y : c.y + c.h, c.x : c.x + c.w] == (10, 20, 30)).all()


def test_bake_page_without_inpaint_leaves_unseen_texels_neutral() -> None:
    d = synthetic_design(resolution=10, texture_size=32)
    view = d.face_view.copy()
    view[:40] = FaceView.NEITHER
    d = replace(d, face_view=view)
    xs, ys, h = grid_of(d)
    lay = layout_page(128, 4, xs, ys, h)
    plain, stats = bake_page(d, lay, wall_rgb=(1, 2, 3), inpaint="none")
    filled, _ = bake_page(d, lay, wall_rgb=(1, 2, 3), inpaint="harmonic")
    assert stats["unseen_fraction"] == pytest.approx(40 / view.size, abs=0.02)
    _, known = bake_top(d, lay)
    t = lay.top
    top_plain = plain[t.y : t.y + t.h, t.x : t.x + t.w]
    top_filled = filled[t.y : t.y + t.h, t.x : t.x + t.w]
    assert (top_plain[~known] == (1, 2, 3)).all()
    assert not (top_filled[~known] == (1, 2, 3)).all(axis=1).any()
    np.testing.assert_array_equal(top_plain[known], top_filled[known])


def test_vertex_colours_follow_the_page() -> None:
    d = synthetic_design(resolution=10, texture_size=32)
    solid = build_solid(d, d.scene.mm_per_unit, FabOptions())
    lay = layout_page(256, 8, solid.grid_x, solid.grid_y, solid.heights)
    uvm = build_uvmap(solid, lay)
    page = np.zeros((256, 256, 3), np.uint8)
    page[...] = (40, 80, 120)
    vc = vertex_colors(solid, uvm, page, lay, (200, 201, 202))
    top_v = np.unique(solid.faces[solid.is_top])
    assert (vc[top_v] == (40, 80, 120)).all()
    rest = np.setdiff1d(np.arange(solid.vertices.shape[0]), top_v)
    assert rest.size and (vc[rest] == (200, 201, 202)).all()


def test_png_bytes_round_trip_and_are_reproducible() -> None:
    img = np.random.default_rng(1).integers(0, 256, (32, 48, 3)).astype(np.uint8)
    a, b = png_bytes(img), png_bytes(img)
    assert a == b
    back = np.asarray(Image.open(io.BytesIO(a)))
    np.testing.assert_array_equal(back, img)


def test_warm_up_compiles_every_kernel() -> None:
    from saucerfab.fabricate import kernels

    names = kernels.warm_up()
    jitted = [n for n in dir(kernels) if hasattr(getattr(kernels, n), "signatures")]
    assert sorted(names) == sorted(jitted)
    assert all(getattr(kernels, n).signatures for n in names)


@pytest.mark.parametrize("shape", ["rectangle", "disc"])
def test_side_charts_stay_far_under_the_tops_texel_density(shape: str) -> None:
    """The sides carry plain colours: at most SIDE_DENSITY_SHARE of the top's texels per mm, so a checker
    takes them for plain (under a tenth of the best density) however large the part's bottom is."""
    from saucerfab.fabricate.atlas import SIDE_DENSITY_SHARE, _px_per_mm
    from saucerfab.model.scene import disc_saucer, round_scene

    scene = replace(round_scene(), saucer=disc_saucer(2.0, 24)) if shape == "disc" else None
    d = synthetic_design(scene, resolution=24, texture_size=32)
    solid = build_solid(d, d.scene.mm_per_unit, FabOptions())
    lay = layout_page(1024, 8, solid.grid_x, solid.grid_y, solid.heights)
    uvm = build_uvmap(solid, lay)
    px = uvm.uvs * 1024
    top = _px_per_mm(solid.vertices, solid.faces[solid.is_top], px, uvm.face_uvs[solid.is_top])
    sides = _px_per_mm(solid.vertices, solid.faces[~solid.is_top], px, uvm.face_uvs[~solid.is_top])
    assert 0 < sides <= SIDE_DENSITY_SHARE * top * (1 + 1e-6)
