"""Tests of saucerfab.imaging.charts and saucerfab.imaging.colormaps: the Pillow-drawn charts of a design's previews."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from saucerfab.imaging.charts import Axis, draw_energy_plot, draw_height_change_map, height_change_map
from saucerfab.imaging.colormaps import SIZE, TABLES, colormap


@pytest.mark.parametrize("name", sorted(TABLES))
def test_colormap_tables_are_matplotlibs(name):
    from matplotlib import colormaps

    x = np.concatenate([np.linspace(0.0, 1.0, 1001), np.random.default_rng(0).random(5000), [-0.5, 1.5]])
    want = np.round(colormaps[name](x)[:, :3] * 255).astype(np.uint8)
    np.testing.assert_array_equal(colormap(name, x), want)
    assert TABLES[name].shape == (SIZE, 3)


def test_colormap_refuses_unknown_names_and_nan():
    with pytest.raises(ValueError, match="viridis"):
        colormap("jet", np.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        colormap("magma", np.array([0.2, np.nan]))


def test_axis_ticks():
    lin = Axis("linear", -0.03, 1.03)
    assert [label for _, label in lin.ticks()] == ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]
    log = Axis("log", -2.2, 5.1)  # 10**-2.2 .. 10**5.1
    assert [v for v, _ in log.ticks()] == [10.0**k for k in range(-2, 6)]
    assert log.ticks()[0][1] == "10**-2"
    narrow = Axis("log", np.log10(150.0), np.log10(900.0))  # under a decade: 1-2-5 steps
    assert [v for v, _ in narrow.ticks()] == [200.0, 500.0]
    sym = Axis("symlog", -2.0, 3.0, linthresh=1.0)
    values = [v for v, _ in sym.ticks()]
    assert 0.0 in values and 10.0 in values and -1.0 in values and values == sorted(values)
    # log of non-positive values has no place on the axis: NaN, not a clamp
    assert np.isnan(log.scaled(np.array([0.0, -1.0]))).all()


def _colour_rows(img: np.ndarray, colour, tol: int = 40) -> np.ndarray:
    near = np.abs(img.astype(int) - np.asarray(colour)).max(axis=-1) <= tol
    return np.nonzero(near)[0]


def test_energy_plot_draws_larger_energies_higher():
    rows = [{"stage": "a", "iteration": i, "time_s": 0.1 * i, "E_total": 1e4 * (1 + 0.01 * i),
             "E_deform": 1e-2 * (1 + 0.01 * i), "E_visual": 0.0 if i == 0 else 5e3} for i in range(30)]
    img, layout = draw_energy_plot(rows, size_px=(600, 360))
    assert layout.y_scale == "log"
    x0, y0, x1, y1 = (int(v) for v in layout.plot)
    inside = img[y0 + 2:y1 - 1, x0 + 2:x1 - 1]
    black = _colour_rows(inside, (0, 0, 0))
    orange = _colour_rows(inside, (255, 127, 14))
    assert black.size and orange.size
    # four decades apart on a log axis: the total far above E_deform
    assert np.median(black) + 0.5 * (y1 - y0) < np.median(orange)
    # E_visual's exact 0 is left out on the log axis, its other rows are drawn
    assert _colour_rows(inside, (31, 119, 180)).size


def test_energy_plot_negative_values_use_symlog_and_errors():
    rows = [{"stage": "s", "iteration": i, "E_total": -5.0 + i, "E_visual": 10.0} for i in range(10)]
    img, layout = draw_energy_plot(rows)
    assert layout.y_scale == "symlog" and img.shape == (420, 720, 3)
    with pytest.raises(ValueError, match="non-empty"):
        draw_energy_plot([])
    with pytest.raises(ValueError, match="160 x 120"):
        draw_energy_plot(rows, size_px=(100, 100))
    # rows with neither time nor iteration: nothing to place them at, no failure
    img, layout = draw_energy_plot([{"stage": "a", "E_total": 1.0}, {"stage": "b", "E_total": 2.0}])
    assert len(layout.stage_labels) == 2
    # a log with no energies at all still gives a page with axes
    img, layout = draw_energy_plot([{"stage": "s", "iteration": 0}])
    assert layout.legend is None and (img < 100).any()


def test_height_change_map_keeps_the_footprints_aspect():
    z = np.zeros((20, 20))
    h = z + np.linspace(0.0, 0.02, 20)[None, :]
    for extent, aspect in (((0.0, 2.0, 0.0, 1.0), 2.0), (None, 1.0), ((-1.0, 1.0, 0.0, 4.0), 0.5)):
        img, (x0, y0, x1, y1), bar = draw_height_change_map(z, h, 0.02, extent=extent, size_px=(480, 400))
        assert (x1 - x0) / (y1 - y0) == pytest.approx(aspect, rel=1e-6)
        assert x1 < bar[0] and bar[2] < 480 and y0 >= 0 and y1 <= 400
        # the change grows along x: viridis' dark end on the left, its bright end on the right
        row = img[int((y0 + y1) / 2)]
        np.testing.assert_allclose(row[int(x0) + 3], TABLES["viridis"][0], atol=3)
        np.testing.assert_allclose(row[int(x1) - 3], TABLES["viridis"][-1], atol=3)
        # the colourbar runs from the top of the scale (top) to 0 (bottom)
        col = img[:, int((bar[0] + bar[2]) / 2)]
        np.testing.assert_allclose(col[int(bar[1]) + 3], TABLES["viridis"][-1], atol=12)
        np.testing.assert_allclose(col[int(bar[3]) - 3], TABLES["viridis"][0], atol=12)
    assert height_change_map(z, h, 0.02).shape == (400, 480, 3)
    with pytest.raises(ValueError, match="colour map"):
        height_change_map(z, h, 0.02, cmap="jet")


def test_drawing_charts_imports_no_plotting_library():
    """A design's previews and verify pictures are drawn without importing matplotlib (half a second)."""
    code = (
        "import sys, numpy as np\n"
        "from saucerfab.imaging.charts import energy_plot, height_change_map\n"
        "from saucerfab.verify.pictures import difference_map\n"
        "energy_plot([{'stage': 's', 'iteration': i, 'E_total': 1.0 + i} for i in range(5)])\n"
        "height_change_map(np.zeros((4, 4)), np.ones((4, 4)) * 0.01, 0.02)\n"
        "difference_map(np.zeros((4, 4, 3)), np.ones((4, 4, 3)), np.ones((4, 4), bool))\n"
        "print('matplotlib' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
