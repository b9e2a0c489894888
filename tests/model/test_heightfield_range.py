"""Shape files whose heights no saucer can have (issue 16).

A ``.npy`` of finite 1e40 values used to reach the optimizer ("starting point
must be strictly feasible"), 1e38 its framing ("view axis is vertical"), each
as a traceback with exit 1. The heightfield's range is checked when the file
loads: a ShapeError naming the range found and the range allowed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from saucerfab.cli import main
from saucerfab.errors import ShapeError
from saucerfab.model.heightfield import load_shape
from saucerfab.model.scene import Saucer

IMAGES = Path(__file__).resolve().parents[2] / "samples" / "batch" / "images"


@pytest.mark.parametrize("value", [1e40, 1e38, -1e38, 1e4])
def test_heights_out_of_range_are_refused_naming_both_ranges(tmp_path: Path, value: float) -> None:
    path = tmp_path / "tall.npy"
    np.save(path, np.full((8, 8), value))
    with pytest.raises(ShapeError) as exc:
        load_shape(path, 8)  # height_scale 0.1
    text = str(exc.value)
    assert "tall.npy" in text
    assert f"{value * 0.1:.4g}" in text  # the range found, in model units
    assert "+-100" in text and "1 x 1 units" in text  # the range allowed, from the saucer's size
    assert "--height-scale" in text


def test_a_value_that_overflows_when_scaled_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "huge.npy"
    np.save(path, np.full((4, 4), 1e300))
    with pytest.raises(ShapeError, match="inf"):
        load_shape(path, 4, height_scale=1e10)


def test_the_allowed_range_follows_the_saucer(tmp_path: Path) -> None:
    path = tmp_path / "s.npy"
    np.save(path, np.linspace(0, 500, 16).reshape(4, 4))
    with pytest.raises(ShapeError, match=r"\+-100 "):
        load_shape(path, 4, height_scale=1.0)
    big = Saucer(x_range=(-5.0, 5.0), y_range=(-15.0, -5.0))
    assert load_shape(path, 4, height_scale=1.0, saucer=big).max() == pytest.approx(500)
    # ordinary shape files load as before (values in [0, 15], as 16-bit PNGs or small arrays give)
    np.save(path, np.arange(16.0).reshape(4, 4))
    assert load_shape(path, 4, height_scale=1.0).max() == 15


def test_a_bad_height_scale_is_refused_for_every_shape() -> None:
    for scale in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ShapeError, match="height_scale must be a positive number"):
            load_shape("waves", 8, height_scale=scale)


@pytest.mark.parametrize("value", [1e40, 1e38])
def test_design_with_such_a_shape_is_exit_2_without_a_traceback(
    tmp_path: Path, value: float, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "tall.npy"
    np.save(path, np.full((8, 8), value))
    code = main(
        ["design", "--direct", str(IMAGES / "ring.png"), "--reflected", str(IMAGES / "star.png"),
         "--shape", str(path), "--resolution", "12", "--image-size", "16", "--max-iters", "2",
         "--no-verify", "-q", "-o", str(tmp_path / "d")]
    )
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and "gives heights from" in err and "tall.npy" in err
    assert not (tmp_path / "d").exists()
