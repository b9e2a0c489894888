"""Tests of saucerfab.fabricate.bleed: the printer's colour bleed on a page, and its compensation.

The blur of a step edge on a plane is the Gaussian's (an erf in linear light)
and stays in its chart; the fast path agrees with the float64 reference;
compensation brings a step's print closer to the step, within the colour
range, and never makes the print worse step by step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from saucerfab.fabricate.atlas import Rect, layout_page
from saucerfab.fabricate.bake import compose_page
from saucerfab.fabricate.bleed import (
    Chart,
    bleed_page,
    bleed_page_reference,
    compensate_bleed,
    compensate_top,
    linear_to_srgb,
    sigma_px,
    srgb_to_linear,
    surface_area_mm2,
    top_px_per_mm,
)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR (dB) of two images in [0, 1]."""
    return 10.0 * math.log10(1.0 / float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def step_page(lo: float, hi: float, h: int = 24, w: int = 96) -> np.ndarray:
    """(h, w, 3) float32 sRGB: ``lo`` left of column w/2, ``hi`` from it on."""
    page = np.full((h, w, 3), lo, np.float32)
    page[:, w // 2:] = hi
    return page


def test_srgb_round_trip() -> None:
    v = np.linspace(0.0, 1.0, 257, dtype=np.float32)
    assert np.abs(linear_to_srgb(srgb_to_linear(v)) - v).max() < 1e-5
    assert srgb_to_linear(np.float32(0.5)) == pytest.approx(0.21404, abs=1e-4)  # the sRGB standard's mid grey


def test_a_step_edge_blurs_into_the_gaussians_erf_and_keeps_within_its_chart() -> None:
    """Black | white in one chart, red in the next, a strip in none: the erf, no red in the white, the strip kept."""
    s_mm, ppm = 0.12, 25.0  # 3 texels, as a J55 page's
    s = sigma_px(ppm, s_mm)
    page = np.zeros((40, 160, 3), np.float32)
    page[:30, 40:80] = 1.0  # chart A: black [0, 40), white [40, 80)
    page[:30, 80:] = (1.0, 0.0, 0.0)  # chart B: red
    page[30:] = 0.5  # in no chart
    out = bleed_page(page, [Rect(0, 0, 80, 30), Rect(80, 0, 80, 30)], ppm, s_mm)
    lin = srgb_to_linear(out[15, :80, 1])
    x = np.arange(80) + 0.5  # texel centres; the edge lies at 40
    want = 0.5 * (1.0 + np.array([math.erf((c - 40.0) / (s * math.sqrt(2.0))) for c in x]))
    inner = slice(int(4 * s) + 1, 80 - int(4 * s) - 1)  # away from the chart's own edges
    assert np.abs(lin[inner] - want[inner]).max() < 0.01
    # the white beside the red chart stays white, the red stays red: colours of other charts never mix
    assert np.abs(out[:30, 60:80] - 1.0).max() < 1e-5
    assert np.abs(out[:30, 80:] - page[:30, 80:]).max() < 1e-5
    assert np.array_equal(out[30:], page[30:])  # outside every chart: unchanged


def test_a_masked_chart_mixes_only_its_own_texels() -> None:
    """A ring-shaped chart around a hole of another colour: the hole's colour never reaches the ring."""
    page = np.zeros((32, 32, 3), np.float32)
    page[...] = (0.0, 0.0, 1.0)  # blue in the hole
    yy, xx = np.mgrid[:32, :32]
    ring = (np.hypot(yy - 15.5, xx - 15.5) > 6) & (np.hypot(yy - 15.5, xx - 15.5) < 14)
    page[ring] = (0.0, 1.0, 0.0)  # a uniform green ring
    out = bleed_page(page, [Chart(Rect(0, 0, 32, 32), ring)], 1.0, 3.0)
    assert np.abs(out[ring] - (0.0, 1.0, 0.0)).max() < 1e-5
    assert np.array_equal(out[~ring], page[~ring])


def test_the_fast_path_matches_the_float64_reference() -> None:
    rng = np.random.default_rng(3)
    page = rng.random((30, 50, 3)).astype(np.float32)
    yy, xx = np.mgrid[:20, :22]
    disc = np.hypot(yy - 9.5, xx - 10.5) < 9
    charts = [Rect(1, 2, 24, 26), Chart(Rect(27, 5, 22, 20), disc)]
    for s_mm in (0.05, 0.1, 0.25):
        fast = bleed_page(page, charts, 20.0, s_mm)
        ref = bleed_page_reference(page, charts, 20.0, s_mm)
        assert np.abs(fast - ref).max() < 2e-5
    page8 = np.clip(np.rint(page * 255), 0, 255).astype(np.uint8)
    fast8 = bleed_page(page8, charts, 20.0, 0.1)
    assert fast8.dtype == np.uint8
    assert np.abs(fast8.astype(np.float64) - bleed_page_reference(page8, charts, 20.0, 0.1) * 255).max() <= 0.51


def test_no_bleed_leaves_the_page_as_it_is() -> None:
    page = np.random.default_rng(0).integers(0, 256, (16, 16, 3), dtype=np.uint8)
    for f in (bleed_page, compensate_bleed):
        assert np.array_equal(f(page, [Rect(0, 0, 16, 16)], 20.0, 0.0), page)
    with pytest.raises(ValueError, match="px_per_mm must be positive"):
        bleed_page(page, [Rect(0, 0, 16, 16)], 0.0, 0.1)


@pytest.mark.parametrize(("lo", "hi", "margin_db"), [(0.25, 0.75, 1.5), (0.0, 1.0, 1.5), (0.2, 0.9, 1.5)])
def test_compensation_brings_a_step_edges_print_closer_to_the_step(lo: float, hi: float, margin_db: float) -> None:
    """Measured on a plane at 2.5 texels of blur: the compensated print is at least ``margin_db`` closer.

    (A Gaussian takes away every frequency above ~1/sigma for good, so a step's print can only come
    part of the way back: 2.0-2.2 dB on these three steps with five steps of the method.)
    """
    page = step_page(lo, hi)
    charts = [Rect(0, 0, page.shape[1], page.shape[0])]
    comp = compensate_bleed(page, charts, 1.0, 2.5)
    assert comp.min() >= 0.0 and comp.max() <= 1.0
    plain = psnr(bleed_page(page, charts, 1.0, 2.5), page)
    better = psnr(bleed_page(comp, charts, 1.0, 2.5), page)
    assert better >= plain + margin_db, (plain, better)
    # as exported: 8 bits
    page8 = np.rint(page * 255).astype(np.uint8)
    comp8 = compensate_bleed(page8, charts, 1.0, 2.5)
    assert comp8.dtype == np.uint8
    assert psnr(bleed_page(comp8, charts, 1.0, 2.5) / 255.0, page) >= plain + margin_db - 0.2


def test_the_print_never_gets_worse_step_by_step() -> None:
    """Isolated white dots on black: the hardest case for the unit step (the sRGB slopes differ most)."""
    page = np.zeros((40, 40, 3), np.float32)
    page[::7, ::7] = 1.0
    page[20:23, 5:35] = (0.9, 0.4, 0.1)
    charts = [Rect(0, 0, 40, 40)]
    scores = [psnr(bleed_page(compensate_bleed(page, charts, 1.0, 2.0, iterations=k, tol=0.0), charts, 1.0, 2.0),
                   page) for k in range(9)]
    assert all(b >= a - 0.01 for a, b in zip(scores, scores[1:])), scores
    assert scores[-1] > scores[0] + 1.0


def test_wiener_stays_in_range_and_an_unknown_method_is_refused() -> None:
    page = step_page(0.0, 1.0)
    out = compensate_bleed(page, [Rect(0, 0, 96, 24)], 1.0, 2.5, method="wiener")
    assert out.min() >= 0.0 and out.max() <= 1.0
    with pytest.raises(ValueError, match="method must be one of"):
        compensate_bleed(page, [Rect(0, 0, 96, 24)], 1.0, 2.5, method="unsharp")  # type: ignore[arg-type]


def test_the_tops_density_and_the_compensated_page_with_its_gutter() -> None:
    xs = np.linspace(0.0, 40.0, 11)
    flat = np.zeros((11, 11))
    assert surface_area_mm2(xs, xs, flat) == pytest.approx(1600.0)
    tilted = np.tile(xs * 0.75, (11, 1))  # rises 3 mm in 4: 5/4 longer along x
    assert surface_area_mm2(xs, xs, tilted) == pytest.approx(2000.0)
    layout = layout_page(128, 4, xs, xs, flat)
    assert top_px_per_mm(layout, xs, xs, flat) == pytest.approx(math.sqrt(layout.top.w * layout.top.h / 1600.0))
    t = layout.top
    top = np.full((t.h, t.w, 3), 60, np.uint8)
    top[:, t.w // 2:] = 200
    page = compose_page(layout, top, (10, 20, 30))
    out = compensate_top(page, layout, 2.0, 1.0)
    new = out[t.y:t.y + t.h, t.x:t.x + t.w]
    assert not np.array_equal(new, top)  # sharpened at the step
    assert np.array_equal(out[t.y - 4:t.y, t.x:t.x + t.w], np.repeat(new[:1], 4, axis=0))  # the gutter: edge texels
    assert np.array_equal(out[t.y:t.y + t.h, t.x + t.w:t.x + t.w + 4], np.repeat(new[:, -1:], 4, axis=1))
    rest = np.ones(page.shape[:2], bool)
    rest[max(t.y - 4, 0):t.y + t.h + 4, max(t.x - 4, 0):t.x + t.w + 4] = False
    assert np.array_equal(out[rest], page[rest])  # the chart column and beyond: as they were


def test_a_meshs_charts_bleed_as_the_export_sees_its_top() -> None:
    """From the mesh alone (what verify reads): the top is one chart at the top's density; walls stay plain."""
    from saucerfab.fabricate.atlas import build_uvmap
    from saucerfab.fabricate.bake import bake_page
    from saucerfab.fabricate.bleed import bleed_mesh_texture, mesh_charts
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.fabricate.solid import build_solid
    from saucerfab.model.design_folder import synthetic_design

    design = synthetic_design(resolution=16, texture_size=64, seed=4)
    solid = build_solid(design, design.scene.mm_per_unit, FabOptions(), None)
    layout = layout_page(256, 4, solid.grid_x, solid.grid_y, solid.heights)
    uvmap = build_uvmap(solid, layout)
    page, _stats = bake_page(design, layout, wall_rgb=(200, 200, 200), inpaint="harmonic")
    charts = mesh_charts(solid.vertices, solid.faces, uvmap.uvs, uvmap.face_uvs, 256)
    t = layout.top
    top = [c for c in charts if c.rect.x <= t.x + 1 and c.rect.w >= t.w - 2]
    assert len(top) == 1 and len(charts) > 1
    ppm = top_px_per_mm(layout, solid.grid_x, solid.grid_y, solid.heights)
    assert top[0].px_per_mm == pytest.approx(ppm, rel=0.02)
    sigma_mm = 1.5 / ppm  # 1.5 texels
    printed = bleed_mesh_texture(page, solid.vertices, solid.faces, uvmap.uvs, uvmap.face_uvs, sigma_mm)
    want = bleed_page(page, [t], ppm, sigma_mm)
    inner = (slice(t.y + 4, t.y + t.h - 4), slice(t.x + 4, t.x + t.w - 4))
    assert np.abs(printed[inner].astype(int) - want[inner].astype(int)).max() <= 2
    assert not np.array_equal(printed[inner], page[inner])
    walls = (slice(None), slice(layout.charts.x, None))
    assert np.array_equal(printed[walls], page[walls])  # one plain colour: a blur keeps it
