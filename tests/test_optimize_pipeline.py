"""End-to-end `saucerfab design` at a small resolution, and its input checks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from saucerfab.cli import main
from saucerfab.design import FaceView, load_design
from saucerfab.errors import ImageError, ShapeError
from saucerfab.optimize.pipeline import run_design
from saucerfab.optimize.request import DesignRequest

SAMPLES = Path(__file__).resolve().parents[1] / "samples"
SMALL = dict(resolution=24, image_size=64, max_iters=25)


@pytest.fixture(scope="module")
def small_design(tmp_path_factory):
    out = tmp_path_factory.mktemp("d") / "design"
    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", shape="waves", **SMALL)
    run_design(req, out, progress=lambda *a: None)
    return req, out


def test_design_folder_is_complete_and_bounded(small_design) -> None:  # noqa: ANN001
    req, out = small_design
    d = load_design(out)
    meta = json.loads((out / "design.json").read_text())
    assert meta["schema"] == "saucerfab.design/1"
    delta = d.scene.saucer.delta
    assert np.abs(d.heights - d.base_heights).max() < delta
    assert [s["name"] for s in meta["metrics"]["stages"]] == ["bw_sigma_large", "bw_sigma_small", "sparse"]
    for st in meta["metrics"]["stages"]:
        for key in ("E_visual", "E_deform", "conflict_fraction", "max_abs_height_change", "iterations", "seconds"):
            assert key in st
        assert st["max_abs_height_change"] < delta
    assert meta["inputs"]["direct"]["sha256"] and meta["inputs"]["reflected"]["sha256"]
    assert meta["metrics"]["rho"] > 0
    w = meta["parameters"]["weights_used"]
    assert w["w_large"] == pytest.approx(0.08 * meta["metrics"]["rho"])
    assert w["lam"] == pytest.approx(6e-5 * meta["metrics"]["rho"])
    for name in ("direct_view", "reflected_view", "composite", "height_change", "side_by_side", "energies"):
        assert (out / "previews" / f"{name}.png").stat().st_size > 500
    assert set(np.unique(d.face_view)) <= {int(v) for v in FaceView}
    # the optimisation lowered the stage energies
    log = [json.loads(x) for x in (out / "energy_log.jsonl").read_text().splitlines()]
    first = [e for e in log if e["stage"] == "bw_sigma_large"]
    assert first[-1]["E_visual"] < first[0]["E_visual"]


def test_design_is_deterministic(small_design, tmp_path) -> None:  # noqa: ANN001
    req, out = small_design
    again = tmp_path / "again"
    run_design(req, again, progress=lambda *a: None)
    assert np.array_equal(np.load(out / "heights.npy"), np.load(again / "heights.npy"))
    assert (out / "texture.png").read_bytes() == (again / "texture.png").read_bytes()


def test_bad_inputs_stop_before_work_and_write_nothing(tmp_path) -> None:
    out = tmp_path / "never"
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 20)  # truncated PNG
    with pytest.raises(ImageError):
        run_design(DesignRequest(bad, SAMPLES / "reflected_star.png", **SMALL), out)
    nan_shape = tmp_path / "nan.npy"
    np.save(nan_shape, np.full((8, 8), np.nan))
    with pytest.raises(ShapeError):
        run_design(DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", shape=str(nan_shape), **SMALL), out)
    assert not out.exists()
    assert not any(p.name.startswith(".never") for p in tmp_path.iterdir())
    # the CLI says so in one line and exits 2
    rc = main(["design", "--direct", str(bad), "--reflected", str(SAMPLES / "reflected_star.png"), "--out", str(out)])
    assert rc == 2
    rc = main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png"),
               "--reflected2", str(SAMPLES / "reflected2_moon.png"), "--out", str(out)])
    assert rc == 2  # a second reflection needs a prism cup
    assert not out.exists()


def test_ctrl_c_keeps_a_checkpoint_and_resume_gives_the_same_design(small_design, tmp_path) -> None:  # noqa: ANN001
    from saucerfab.errors import Interrupted

    req, reference = small_design
    out = tmp_path / "design"

    def interrupt(stage, it, max_it, parts, elapsed):  # noqa: ANN001
        if stage == "bw_sigma_small":
            raise KeyboardInterrupt

    with pytest.raises(Interrupted):
        run_design(req, out, progress=interrupt, log_every_s=0.0)
    assert not out.exists()  # no half-written design folder
    assert (tmp_path / ".design.checkpoint" / "state.npz").is_file()
    run_design(req, out, progress=lambda *a: None)
    assert not (tmp_path / ".design.checkpoint").exists()
    assert np.array_equal(np.load(out / "heights.npy"), np.load(reference / "heights.npy"))


def test_without_times_the_design_folder_is_byte_identical(tmp_path) -> None:  # noqa: ANN001
    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png",
                        resolution=16, image_size=48, max_iters=8, record_times=False)
    a, b = tmp_path / "a", tmp_path / "b"
    run_design(req, a, progress=lambda *x: None)
    run_design(req, b, progress=lambda *x: None)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    assert "total_s" not in json.loads((a / "design.json").read_text())["metrics"]


def test_an_unrelated_output_folder_or_file_is_never_replaced(tmp_path) -> None:  # noqa: ANN001
    from saucerfab.errors import ConfigError

    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png",
                        resolution=8, image_size=16, max_iters=2)
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "thesis.txt").write_text("precious")
    with pytest.raises(ConfigError, match="not a design folder"):
        run_design(req, folder)
    assert (folder / "thesis.txt").read_text() == "precious"
    a_file = tmp_path / "notes.txt"
    a_file.write_text("keep")
    with pytest.raises(ConfigError, match="existing file"):
        run_design(req, a_file)
    assert a_file.read_text() == "keep"
    # an earlier design folder is replaced, as a rerun should
    run_design(req, tmp_path / "d", progress=lambda *a: None)
    run_design(req, tmp_path / "d", progress=lambda *a: None)
    assert (tmp_path / "d" / "design.json").is_file()
