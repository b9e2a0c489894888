"""The looks of a running design (issue 18): a first look before any stage, a refined one after each."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from saucerfab.cli import main
from saucerfab.optimize.prepare import prepare
from saucerfab.optimize.request import DesignRequest
from saucerfab.workflow import run_design

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
TINY = dict(resolution=24, image_size=48, max_iters=2, record_times=False)
VIEWS = ("direct", "reflected", "composite")


def _request() -> DesignRequest:
    return DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", **TINY)


def _grey(rgb: np.ndarray) -> np.ndarray:
    return (np.asarray(rgb, np.float64)[..., :3] @ [0.299, 0.587, 0.114]).ravel()


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(_grey(a), _grey(b))[0, 1])


@pytest.fixture(scope="module")
def looked(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[str, dict[str, bytes], float]]]:
    """A tiny design whose look callback keeps each call's stage, PNG bytes and elapsed time."""
    out = tmp_path_factory.mktemp("looks") / "design"
    calls: list[tuple[str, dict[str, bytes], float]] = []

    def look(stage: str, files: dict[str, Path], elapsed_s: float) -> None:
        assert all(p.parent == out.parent / ".design.checkpoint" / "previews" for p in files.values())
        calls.append((stage, {k: p.read_bytes() for k, p in files.items()}, elapsed_s))

    run_design(_request(), out, progress=lambda *a: None, look=look)
    return out, calls


def test_the_first_look_comes_first_then_one_per_stage(looked) -> None:  # noqa: ANN001
    out, calls = looked
    stages = [s["name"] for s in json.loads((out / "design.json").read_text())["metrics"]["stages"]]
    assert [c[0] for c in calls] == ["first_look", *stages]
    elapsed = [c[2] for c in calls]
    assert elapsed == sorted(elapsed) and elapsed[0] >= 0
    for _, files, _ in calls:
        assert sorted(files) == sorted(VIEWS)
        for data in files.values():
            img = Image.open(io.BytesIO(data))
            assert img.format == "PNG" and img.size == (48, 48) and img.mode == "RGB"
    # the looks lived in the run's checkpoint folder, which goes at the end
    assert not (out.parent / ".design.checkpoint").exists()
    assert not (out / "previews" / "first_look_direct.png").exists()


def _mse(a: np.ndarray, b: np.ndarray) -> float:
    """Mean squared difference over all three channels (a red heart and a yellow star differ in colour)."""
    return float(np.mean((np.asarray(a, np.float64)[..., :3] - np.asarray(b, np.float64)[..., :3]) ** 2))


def test_every_look_shows_the_designers_pictures(looked) -> None:  # noqa: ANN001
    _, calls = looked
    prep = prepare(_request())
    # the pictures as meant (fitted, flattened), not the black-white targets the first stages aim at
    direct, reflected = prep.render["direct"], prep.render["reflected"]
    for stage, files, _ in calls:
        look = {k: np.asarray(Image.open(io.BytesIO(v)), np.float64) / 255 for k, v in files.items()}
        # the direct view shows the direct picture (the red heart), not the reflected one (the yellow star)
        assert 2 * _mse(look["direct"], direct) < _mse(look["direct"], reflected), stage
        assert 2 * _mse(look["reflected"], reflected) < _mse(look["reflected"], direct), stage
        # no trace of the enhancement's blue background: the pictures have none
        blue = (look["direct"][..., 2] > 0.8) & (look["direct"][..., 0] < 0.3)
        assert blue.mean() < 0.02, stage


def test_a_failing_look_neither_stops_nor_changes_the_design(
    looked, tmp_path: Path, capsys: pytest.CaptureFixture[str]  # noqa: ANN001
) -> None:
    reference, _ = looked
    out = tmp_path / "design"
    calls: list[str] = []

    def broken(stage: str, files: dict[str, Path], elapsed_s: float) -> None:
        calls.append(stage)
        raise RuntimeError("the viewer crashed")

    run_design(_request(), out, progress=lambda *a: None, look=broken)
    err = capsys.readouterr().err
    assert err.count("the look callback raised RuntimeError: the viewer crashed") == 1  # said once
    assert calls[0] == "first_look" and len(calls) > 1  # still called after it failed
    # the same design as with a working look (and with none: the other tests' designs agree with it)
    for name in ("heights.npy", "texture.png", "design.json", "face_uvs.npy"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    assert not (tmp_path / ".design.checkpoint").exists()


def test_the_cli_says_when_the_first_look_is_ready(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png"),
            "--resolution", "12", "--image-size", "32", "--max-iters", "2", "--no-verify", "--no-times"]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if x.startswith("first look after ")]
    assert len(lines) == 1 and lines[0].endswith(str(tmp_path / ".a.checkpoint" / "previews"))
    assert main([*args, "-o", str(tmp_path / "b"), "-q"]) == 0
    assert "first look" not in capsys.readouterr().err
