"""The relief's shading and its compensation at export (``--shading-compensation``, issue 45)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.fabricate import shading as sh
from saucerfab.fabricate.atlas import layout_page, top_uv
from saucerfab.fabricate.bleed import linear_to_srgb, srgb_to_linear
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.pipeline import ExportResult, export_design
from saucerfab.model.design import Design
from saucerfab.model.design_folder import save_design, synthetic_design
from saucerfab.verify.lighting import Lamp, LampPlacement, place_lamp


def _grid(n: int, side: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    xs = np.linspace(0.0, side, n)
    x, y = np.meshgrid(xs, xs)
    return xs, xs.copy(), x, y


def test_a_flat_or_tilted_plane_sees_the_whole_sky() -> None:
    xs, ys, x, y = _grid(21, 20.0)
    flat = np.zeros_like(x)
    assert np.array_equal(sh.ambient_occlusion(xs, ys, flat), np.ones_like(flat))
    tilted = 0.7 * x + 0.3 * y + 2.0
    pts, nrm = sh.face_points(sh.Relief.of(xs, ys, tilted))
    # the plane's own horizon is its tangent plane: exact per azimuth
    np.testing.assert_allclose(sh.ambient_occlusion(xs, ys, tilted, points=pts, normals=nrm), 1.0, atol=1e-9)


@pytest.mark.parametrize("k", [0.5, 1.0, 2.0])
def test_the_bottom_of_a_v_groove_sees_cos2_of_its_slope(k: float) -> None:
    """A point on one face at the bottom of an infinite V groove (faces rising at atan k) sees the sky in
    the wedge between them: the 2-D view factor (sin phi2 - sin phi1) / 2 = (1 + cos 2a) / 2 = cos^2 a."""
    xs, ys = np.linspace(-20.0, 20.0, 41), np.linspace(-30.0, 30.0, 61)
    x, _y = np.meshgrid(xs, ys)
    heights = k * np.abs(x)
    expected = 1.0 / (1.0 + k * k)
    normal = np.array([[k, 0.0, 1.0]])  # the face rising to -x
    ao = sh.ambient_occlusion(xs, ys, heights, 16, points=np.zeros((1, 3)), normals=normal)
    assert ao[0] == pytest.approx(expected, abs=2e-3)


def ambient_occlusion_reference(xs_mm: np.ndarray, ys_mm: np.ndarray, heights_mm: np.ndarray, points: np.ndarray,
                                normals: np.ndarray, directions: int = sh.DIRECTIONS, elevations: int = 180,
                                step_cells: float = 0.1) -> np.ndarray:
    """:func:`~saucerfab.fabricate.shading.ambient_occlusion` the slow, obvious way (a few points only).

    For each point, azimuth and elevation (``elevations`` midpoints over (-pi/2, pi/2)) in front of the
    surface, a ray marched in steps of ``step_cells`` cells until it leaves the grid or rises above the
    relief's top; blocked when it passes under the surface. The unblocked ``cos(normal) cos(elevation)``
    summed, over pi.

    Args:
        points, normals: (P, 3), mm and unit.

    Returns:
        (P,)
    """
    relief = sh.Relief.of(xs_mm, ys_mm, heights_mm)
    top = float(relief.heights.max())
    step = step_cells * min(relief.dx, relief.dy)
    de, dphi = math.pi / elevations, 2 * math.pi / directions
    out = []
    for p, n in zip(np.asarray(points, np.float64), np.asarray(normals, np.float64), strict=True):
        n = n / np.linalg.norm(n)
        acc = 0.0
        for k in range(directions):
            phi = 2 * math.pi * (k + 0.5) / directions
            for m in range(elevations):
                e = -math.pi / 2 + (m + 0.5) * de
                w = np.array([math.cos(e) * math.cos(phi), math.cos(e) * math.sin(phi), math.sin(e)])
                cos_n = float(n @ w)
                if cos_n <= 0:
                    continue
                s, blocked = step, False
                while True:
                    q = p + s * w
                    if q[2] > top:
                        break
                    z, inside = relief.height_at(np.array(q[0]), np.array(q[1]))
                    if not inside:
                        break
                    if q[2] < float(z):
                        blocked = True
                        break
                    s += step
                if not blocked:
                    acc += cos_n * math.cos(e) * de * dphi
        out.append(min(acc / math.pi, 1.0))
    return np.array(out)


def test_the_horizon_kernel_matches_brute_ray_marching() -> None:
    xs, ys, x, y = _grid(9, 8.0)
    heights = 1.2 * np.sin(0.9 * x) * np.cos(0.7 * y) + 0.5 * np.sin(0.5 * x + 1.3 * y)
    pts, nrm = sh.face_points(sh.Relief.of(xs, ys, heights))
    pick = np.random.default_rng(0).choice(pts.reshape(-1, 3).shape[0], 6, replace=False)
    p, n = pts.reshape(-1, 3)[pick], nrm.reshape(-1, 3)[pick]
    fast = sh.ambient_occlusion(xs, ys, heights, 8, points=p, normals=n)
    slow = ambient_occlusion_reference(xs, ys, heights, p, n, directions=8, elevations=90)
    assert slow.min() < 0.9  # the field occludes: the comparison means something
    # the kernel's steps grow (it may step over a thin crest the reference's fine steps meet): 0.02
    np.testing.assert_allclose(fast, slow, atol=0.02)


def test_the_lamp_reads_its_power_on_a_flat_paper_at_the_foot() -> None:
    """One definition of brightness with verify: a white paper at the cup's foot reads the lamp's power."""
    xs, ys, x, _y = _grid(11, 100.0)
    foot = np.array([50.0, 50.0, 3.0])
    lamp = place_lamp(Lamp((0.0, 300.0, 900.0), 600.0, 0.6), foot, (0.0, -1.0))
    reading = sh.lamp_reading(xs, ys, np.full_like(x, 3.0), lamp, points=foot[None], normals=np.array([[0, 0, 1.0]]))
    assert reading[0] == pytest.approx(0.6, rel=2e-3)


def test_a_wall_hides_the_lamp_behind_it() -> None:
    xs, ys, _x, y = _grid(41, 40.0)
    heights = np.where((y > 18.0) & (y < 22.0), 30.0, 0.0)  # a wall along x
    lamp = LampPlacement(np.array([20.0, 200.0, 60.0]), np.array([20.0, 20.0, 0.0]), 1.0, 1.0)
    before, behind = np.array([[20.0, 30.0, 0.0]]), np.array([[20.0, 10.0, 0.0]])
    up = np.array([[0.0, 0.0, 1.0]])
    assert sh.lamp_reading(xs, ys, heights, lamp, points=before, normals=up)[0] > 0
    assert sh.lamp_reading(xs, ys, heights, lamp, points=behind, normals=up)[0] == 0.0


def test_texel_faces_inverts_the_planar_map() -> None:
    """Each top triangle's centroid, placed on the page by the bake's own map (top_uv), finds that triangle."""
    xs, ys, x, y = _grid(13, 24.0)
    heights = 2.0 * np.sin(x / 3.0) + np.cos(y / 2.0)
    layout = layout_page(256, 4, xs, ys, heights)
    pts, _n = sh.face_points(sh.Relief.of(xs, ys, heights))
    uv = top_uv(layout, xs, ys, pts.reshape(-1, 3)[:, :2])
    col = np.floor(uv[:, 0] * layout.size).astype(int) - layout.top.x
    row = np.floor((1.0 - uv[:, 1]) * layout.size).astype(int) - layout.top.y
    tri, i, j = sh.texel_faces(layout, xs.size, ys.size)
    k, ii, jj = np.indices(pts.shape[:3]).reshape(3, -1)
    assert np.array_equal(tri[row, col], k) and np.array_equal(i[row, col], ii) and np.array_equal(j[row, col], jj)


def test_compensating_a_known_shading_pattern_recovers_the_picture() -> None:
    """A sinusoidal relief (ridges along x) under a small lamp in front: its stripes from the analytic
    cosine term; the page compensated with the computed shading, then lit by the analytic one, is the
    picture up to one gain where it is in the printer's range (all of the pattern: power 1; this page
    fits all but 0.5 % of its texel channels with a factor under MAX_DARKENING).

    The analytic term is taken at each flat face's own slope (the secant over its cell: the sinusoid's
    slope at the cell's middle) and a point lamp; what remains is the lamp's size (10 mm at ~430 mm:
    ~1e-4 of the cosine integral) and the faces' positions (centroids vs cell middles). It reads 76 dB
    on the 98.5 % of texels in range (26.5 dB uncompensated); 50 dB, an rms error of 0.3 % of full
    scale, leaves room for a platform's arithmetic. (Both triangles of a cell share
    their slope on this relief: the texel -> triangle map is tested on its own above.)
    """
    xs, ys, _x, y = _grid(97, 96.0)
    wavelength = 24.0
    amp = 0.6 * wavelength / (2 * math.pi)  # slopes up to 0.6
    heights = 5.0 + amp * np.sin(2 * math.pi * y / wavelength)
    relief = sh.Relief.of(xs, ys, heights)
    lamp = LampPlacement(np.array([48.0, -100.0, 400.0]), np.array([48.0, 48.0, 0.0]), 10.0, 500.0)
    pts, nrm = sh.face_points(relief)
    computed = sh.lamp_reading(xs, ys, heights, lamp, points=pts, normals=nrm)

    mid_y = np.broadcast_to((ys[:-1] + 0.5)[None, :, None], pts.shape[:3])
    g = amp * 2 * math.pi / wavelength * np.cos(2 * math.pi * mid_y / wavelength)
    normal = np.stack([np.zeros_like(g), -g, np.ones_like(g)], -1) / np.sqrt(1 + g * g)[..., None]
    to_lamp = lamp.center - pts
    r = np.linalg.norm(to_lamp, axis=-1)
    lamp_normal = (lamp.target - lamp.center) / np.linalg.norm(lamp.target - lamp.center)
    cos_p = np.sum(normal * to_lamp, -1) / r
    cos_l = -(to_lamp @ lamp_normal) / r
    truth = lamp.radiance / math.pi * lamp.size_mm**2 * cos_p * cos_l / r**2
    sigma = sh.smooth_sigma_mm(xs, ys)
    p_true = sh.shading_pattern(truth, xs, ys, sigma)
    assert p_true.min() < 0.75 and p_true.max() > 1.15  # strong stripes

    layout = layout_page(512, 4, xs, ys, heights)
    u, v = np.meshgrid(np.linspace(0, 1, layout.size), np.linspace(0, 1, layout.size))
    page = np.stack([0.1 + 0.85 * u, 0.5 + 0.4 * np.sin(9 * v), np.where((u * 7 % 1 < 0.5) ^ (v * 5 % 1 < 0.5),
                                                                         0.9, 0.2)], -1).astype(np.float32)
    # all of the pattern (power 1); this page fits with a factor under MAX_DARKENING: nearly nothing clips
    comp, stats = sh.compensate_page(page, layout, sh.shading_pattern(computed, xs, ys, sigma), power=1.0)
    assert stats["global_factor"] > 1.0 and stats["clipped_share"] < 0.01
    assert stats["brightness_ratio"] > 1.0 / sh.MAX_DARKENING
    t = layout.top
    tri, i, j = sh.texel_faces(layout, xs.size, ys.size)
    top = comp[t.y:t.y + t.h, t.x:t.x + t.w]
    lit = srgb_to_linear(top) * p_true[tri, i, j][..., None]
    want = srgb_to_linear(page[t.y:t.y + t.h, t.x:t.x + t.w])
    fits = (top < 1.0 - 1e-6).all(axis=-1)  # the texels the printer's range holds
    assert fits.mean() > 0.95
    gain = float(np.sum(lit[fits] * want[fits]) / np.sum(want[fits] ** 2))
    err = linear_to_srgb(lit[fits] / gain) - linear_to_srgb(want[fits])
    psnr = 10 * math.log10(1.0 / float(np.mean(err**2)))
    assert gain == pytest.approx(1.0 / stats["global_factor"], rel=1e-3)
    before = linear_to_srgb(want * p_true[tri, i, j][..., None] / float(np.mean(p_true))) - linear_to_srgb(want)
    assert 10 * math.log10(1.0 / float(np.mean(before**2))) < 30  # uncompensated, the stripes cost
    assert psnr > 50, psnr


def _lit_psnr(page: np.ndarray, lit: np.ndarray) -> float:
    """PSNR (dB, sRGB) of a lit top against the page after one gain per channel, as verify's lit score."""
    want = srgb_to_linear(page)
    gain = np.sum(lit * want, axis=(0, 1)) / np.sum(want * want, axis=(0, 1))
    return 10 * math.log10(1.0 / float(np.mean((linear_to_srgb(lit / gain) - linear_to_srgb(want)) ** 2)))


@pytest.mark.parametrize("level", [0.25, 0.9])
def test_the_default_rule_keeps_the_print_bright_and_helps(level: float) -> None:
    """A stripe pattern of 0.6-1.5x over a dim page (everything fits: no darkening beyond the percentile's)
    and over a light one (the darkening bound holds: the mean albedo MAX_DARKENING down, no more)."""
    side = 64
    xs = np.linspace(0.0, 64.0, side + 1)
    layout = layout_page(256, 4, xs, xs, np.zeros((side + 1, side + 1)))
    pattern = np.broadcast_to((1.05 + 0.45 * np.sin(np.arange(side) / 2.0))[None, :, None], (2, side, side))
    u, v = np.meshgrid(np.linspace(0, 1, layout.size), np.linspace(0, 1, layout.size))
    page = np.clip(level + 0.1 * np.stack([np.sin(7 * u), np.cos(5 * v), np.sin(3 * (u + v))], -1),
                   0, 1).astype(np.float32)
    comp, stats = sh.compensate_page(page, layout, pattern)
    t = layout.top
    tri, i, j = sh.texel_faces(layout, side + 1, side + 1)
    p = pattern[tri, i, j][..., None]
    plain, top = page[t.y:t.y + t.h, t.x:t.x + t.w], comp[t.y:t.y + t.h, t.x:t.x + t.w]
    ratio = float(srgb_to_linear(top).mean() / srgb_to_linear(plain).mean())
    assert stats["brightness_ratio"] == pytest.approx(ratio, rel=1e-4) and ratio >= 1 / sh.MAX_DARKENING - 1e-3
    if level < 0.5:
        assert stats["clipped_share"] < 0.01 and ratio > 0.9
    else:
        assert ratio == pytest.approx(1 / sh.MAX_DARKENING, rel=0.01) and stats["clipped_share"] > 0.01
    before, after = _lit_psnr(plain, srgb_to_linear(plain) * p), _lit_psnr(plain, srgb_to_linear(top) * p)
    assert after > before + 5, (before, after)


# --------------------------------------------------------------------------- the export option

ATLAS = 256


@pytest.fixture(scope="module")
def design() -> Design:
    return synthetic_design(resolution=24, texture_size=64, seed=2)


def export(design: Design, out: Path, **options: object) -> ExportResult:
    return export_design(design, out, printer="j55", formats=["3mf"],
                         options=FabOptions(texture_px=ATLAS, **options))  # type: ignore[arg-type]


def files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_off_is_the_export_as_before_and_on_is_recorded(design: Design, tmp_path: Path) -> None:
    default = export(design, tmp_path / "default")
    off = export(design, tmp_path / "off", shading_compensation="off")
    assert files(default.out) == files(off.out)  # byte for byte
    summary_off = json.loads(off.summary_json.read_text())
    assert "shading" not in summary_off and "shading_compensation" not in summary_off["options"]
    assert "shading" not in off.timings
    for light in ("ambient", "room"):
        on = export(design, tmp_path / light, shading_compensation=light)
        summary = json.loads(on.summary_json.read_text())
        assert summary["options"]["shading_compensation"] == light
        block = summary["shading"]
        assert block["light"]["kind"] == light and block["global_factor"] >= 1.0
        assert 0.0 <= block["clipped_share"] < 0.3 and block["per_view"] is True
        assert block["brightness_ratio"] >= 1 / sh.MAX_DARKENING - 1e-3 and block["power"] == sh.COMPENSATION_POWER
        assert summary["files"]["saucer.3mf"]["sha256"] != summary_off["files"]["saucer.3mf"]["sha256"]


def test_a_bad_setting_is_refused() -> None:
    with pytest.raises(ConfigError, match="shading_compensation must be one of 'off', 'ambient', 'room', got 'lamp'"):
        FabOptions(shading_compensation="lamp")  # type: ignore[arg-type]


def test_the_cli_flag(design: Design, tmp_path: Path) -> None:
    folder = tmp_path / "design"
    save_design(design, folder)
    out = tmp_path / "print"
    code = main(["export", str(folder), "-o", str(out), "--texture-px", str(ATLAS), "--shading-compensation", "room",
                 "--no-check", "--no-verify", "-q"])
    assert code == 0
    summary = json.loads((out / "export.json").read_text())
    assert summary["options"]["shading_compensation"] == "room" and summary["shading"]["light"]["lamp"]["power"] > 0
    with pytest.raises(SystemExit):
        main(["export", str(folder), "-o", str(tmp_path / "x"), "--shading-compensation", "lamp"])
