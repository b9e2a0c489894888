"""Tests of saucerfab.imaging.panels: PNG bytes, height-change maps, panels, overlays, energy plots, HTML."""

from __future__ import annotations

import base64
import io
import re

import numpy as np
import pytest
from PIL import Image

from saucerfab.imaging.charts import draw_energy_plot, elapsed
from saucerfab.imaging.colormaps import TABLES
from saucerfab.imaging.panels import (
    as_uint8_rgb,
    composite,
    energy_plot,
    height_change_map,
    mask_overlay,
    side_by_side,
    to_png_bytes,
)
from saucerfab.pages.html import Section, html_report


def decode_png(data: bytes) -> np.ndarray:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(io.BytesIO(data)) as im:
        im.load()
        return np.asarray(im.convert("RGB"))


# --------------------------------------------------------------------------- PNG


def test_to_png_bytes_round_trips_uint8_and_float():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (9, 13, 3), dtype=np.uint8)
    np.testing.assert_array_equal(decode_png(to_png_bytes(a)), a)
    f = a.astype(np.float32) / 255.0
    np.testing.assert_array_equal(decode_png(to_png_bytes(f)), a)
    # out-of-range floats are clipped, not wrapped
    assert decode_png(to_png_bytes(np.full((2, 2, 3), 1.7)))[0, 0].tolist() == [255, 255, 255]


def test_as_uint8_rgb_kinds():
    assert as_uint8_rgb(np.array([[True, False]])).tolist() == [[[255] * 3, [0] * 3]]
    assert as_uint8_rgb(np.array([[0.5]]))[0, 0].tolist() == [128, 128, 128]
    rgba = np.zeros((1, 1, 4), np.float32)  # transparent black over white = white
    assert as_uint8_rgb(rgba)[0, 0].tolist() == [255, 255, 255]
    assert as_uint8_rgb(np.array([[65535]], np.uint16))[0, 0].tolist() == [255, 255, 255]
    with pytest.raises(ValueError):
        as_uint8_rgb(np.array([[np.nan]]))
    with pytest.raises(ValueError):
        as_uint8_rgb(np.zeros((2, 2, 2)))


# --------------------------------------------------------------------------- height change map


def _near(img: np.ndarray, colour, tol: int = 12) -> np.ndarray:
    return (np.abs(img.astype(int) - np.asarray(colour)).max(axis=-1) <= tol)


def test_height_change_map_shape_colours_and_orientation():
    n = 40
    z = np.zeros((n, n))
    h = z.copy()
    h[-8:] = 0.02  # the far edge (largest y, last rows) moved by delta
    img = height_change_map(z, h, delta=0.02, size_px=(480, 400))
    assert img.shape == (400, 480, 3) and img.dtype == np.uint8
    top, bottom = TABLES["viridis"][-1], TABLES["viridis"][0]
    hi = _near(img, top)
    lo = _near(img, bottom)
    # in the map area: the changed rows are above (smaller image rows than) the unchanged
    # ones, as the viewer sees the saucer, far edge on top. The colourbar holds both
    # colours too, so compare the map's column band only (left 60 %).
    band = slice(0, int(0.6 * img.shape[1]))
    rows_hi = np.nonzero(hi[:, band])[0]
    rows_lo = np.nonzero(lo[:, band])[0]
    assert rows_hi.size > 200 and rows_lo.size > 1000
    assert rows_hi.mean() < rows_lo.mean()
    # about 8 / 40 of the map is changed
    assert 0.1 < rows_hi.size / (rows_hi.size + rows_lo.size) < 0.3


def test_height_change_map_model_units_and_errors():
    z = np.zeros((5, 5))
    img = height_change_map(z, z + 0.01, 0.02, units="model", extent=(-0.5, 0.5, -1.5, -0.5), size_px=(300, 260))
    assert img.shape == (260, 300, 3)
    with pytest.raises(ValueError):
        height_change_map(z, np.zeros((4, 4)), 0.02)
    with pytest.raises(ValueError):
        height_change_map(z, z, 0.0)


# --------------------------------------------------------------------------- panels


def test_side_by_side_layout():
    red = np.zeros((50, 100, 3), np.uint8)
    red[...] = (255, 0, 0)
    blue = np.zeros((100, 100, 3), np.float32)
    blue[..., 2] = 1.0
    gap, height, title_px = 8, 64, 16
    out = side_by_side([("red", red), ("blue", blue)], height=height, gap=gap, title_px=title_px)
    band = title_px + 8
    assert out.shape == (height + band + 2 * gap, 128 + 64 + 3 * gap, 3)
    y0 = gap + band
    assert out[y0 + 10, gap + 10].tolist() == [255, 0, 0]
    assert out[y0 + 10, gap + 128 + gap + 10].tolist() == [0, 0, 255]
    title_band = out[gap : gap + band, gap : gap + 128]
    assert (title_band < 128).any()  # a title was drawn
    with pytest.raises(ValueError):
        side_by_side([])


def test_mask_overlay():
    img = np.full((20, 20, 3), 0.5, np.float32)
    m = np.zeros((20, 20), bool)
    m[5:15, 5:15] = True
    out = mask_overlay(img, m, colour=(1.0, 0.0, 0.0), opacity=0.5)
    assert out[0, 0].tolist() == [128, 128, 128]  # background untouched
    g = 128 / 255  # the grey as stored in 8 bits
    tint = np.round((np.array([g, g, g]) * 0.5 + np.array([1.0, 0.0, 0.0]) * 0.5) * 255)
    assert out[10, 10].tolist() == tint.tolist() == [192, 64, 64]
    assert out[5, 10].tolist() == [255, 0, 0]  # boundary in solid colour
    with pytest.raises(ValueError):
        mask_overlay(img, np.zeros((3, 3), bool))


def test_composite():
    a = np.zeros((4, 4, 3), np.uint8)
    b = np.full((4, 4, 3), 200, np.uint8)
    alpha = np.array([[0, 1, 0.5, 0.25]] * 4, np.float32)
    out = composite(a, b, alpha)
    assert out[0].tolist() == [[0] * 3, [200] * 3, [100] * 3, [50] * 3]
    with pytest.raises(ValueError):
        composite(a, b, np.zeros((3, 3)))


# --------------------------------------------------------------------------- energies


def _log(per_stage_clock: bool, negative: bool = False) -> list[dict]:
    rows, t = [], 0.0
    for stage, n in (("bw_sigma_large", 30), ("bw_sigma_small", 20), ("sparse", 25)):
        for i in range(n):
            t += 0.05
            rows.append(
                {
                    "stage": stage,
                    "iteration": i,
                    "time_s": i * 0.05 if per_stage_clock else t,
                    "E_visual": 1000.0 * np.exp(-i / 10) + 20,
                    "E_deform": 0.1 * i,  # 0 at the first iteration
                    "E_sparse": 0.01 * i if stage == "sparse" else None,
                    "E_total": (-5.0 if negative else 1.0) + 1000.0 * np.exp(-i / 10),
                }
            )
    return rows


@pytest.mark.parametrize("per_stage_clock", [False, True])
def test_energy_plot_decodes(per_stage_clock):
    png = energy_plot(_log(per_stage_clock), size_px=(600, 350))
    img = decode_png(png)
    assert img.shape == (350, 600, 3)
    assert (img < 100).any() and (img > 250).any()  # something drawn on a light page


def test_energy_plot_negative_energies_and_missing_time():
    rows = _log(False, negative=True)
    for r in rows:
        del r["time_s"]
    assert decode_png(energy_plot(rows)).ndim == 3
    with pytest.raises(ValueError):
        energy_plot([])


def test_energy_plot_stage_labels_do_not_overlap():
    # three short stages: they start a few pixels apart on a long run's time axis
    rows = [{"stage": s, "iteration": i, "time_s": t0 + 0.01 * i, "E_visual": 100.0 - i, "E_total": 120.0 - i}
            for s, t0 in (("bw_sigma_large", 0.0), ("bw_sigma_small", 0.03), ("sparse", 0.06)) for i in range(3)]
    rows.append({"stage": "sparse", "iteration": 3, "time_s": 5.0, "E_visual": 90.0, "E_total": 110.0})
    img, layout = draw_energy_plot(rows, size_px=(720, 420))
    assert img.shape == (420, 720, 3)
    boxes = layout.stage_labels
    assert len(boxes) == 3
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            a, b = boxes[i], boxes[j]
            assert a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1], (i, j)
    # they stay inside the plot, and the legend covers none of them
    px0, py0, px1, py1 = layout.plot
    assert all(px0 <= b[0] and b[2] <= px1 and py0 <= b[1] and b[3] <= py1 for b in boxes)
    lg = layout.legend
    assert lg is not None and all(lg[2] <= b[0] or b[2] <= lg[0] or lg[3] <= b[1] or b[3] <= lg[1] for b in boxes)
    # the names were drawn: dark ink in each box
    for x0, y0, x1, y1 in boxes:
        assert (img[int(y0):int(y1) + 1, int(x0):int(x1) + 1] < 128).any()


def test_elapsed_chains_per_stage_clocks():
    x = elapsed(_log(per_stage_clock=True))
    assert (np.diff(x) >= 0).all()
    np.testing.assert_allclose(x[-1], elapsed(_log(per_stage_clock=False))[-1] - 3 * 0.05, atol=1e-9)


# --------------------------------------------------------------------------- HTML


def test_html_report_embeds_and_escapes():
    png = to_png_bytes(np.zeros((3, 3, 3), np.uint8))
    doc = html_report(
        [
            Section("Inputs <b>", text="a & b", images=[("direct", png), ("linked", "previews/x.png")]),
            {"title": "Metrics", "table": {"E_visual": 12.5, "<k>": "<v>"}},
        ],
        title="Design 1",
    )
    assert doc.startswith("<!DOCTYPE html>") and doc.rstrip().endswith("</html>")
    assert "Inputs &lt;b&gt;" in doc and "a &amp; b" in doc and "&lt;k&gt;" in doc
    assert 'src="previews/x.png"' in doc
    m = re.search(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', doc)
    assert m is not None
    assert decode_png(base64.b64decode(m.group(1))).shape == (3, 3, 3)
    assert "<td>12.5</td>" in doc
