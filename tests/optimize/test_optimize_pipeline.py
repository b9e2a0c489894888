"""End-to-end `saucerfab design` at a small resolution, and its input checks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from saucerfab.cli import main
from saucerfab.errors import ConfigError, ImageError, ShapeError
from saucerfab.model.design import FaceView
from saucerfab.model.design_folder import load_design
from saucerfab.optimize.request import DesignRequest
from saucerfab.workflow import run_design

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
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
    # the default method, auto: pictures with a subject skip the small-sigma stage; every stage capped
    assert [s["name"] for s in meta["metrics"]["stages"]] == ["bw_sigma_large", "sparse"]
    assert meta["parameters"]["method"] == "auto" and meta["parameters"]["method_used"] == "auto"
    assert meta["parameters"]["max_iters_used"] == req.max_iters
    assert all(st["iterations"] <= req.max_iters for st in meta["metrics"]["stages"])
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


def _as_numba_surfaces_it() -> None:
    """A Ctrl-C landing as a numba kernel returns: CPython's SystemError with the KeyboardInterrupt as cause."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as exc:
        raise SystemError("CPUDispatcher(<function _face_setup>) returned a result with an exception set") from exc


@pytest.mark.parametrize("how", ["KeyboardInterrupt", "SystemError from KeyboardInterrupt"])
def test_ctrl_c_keeps_a_checkpoint_and_resume_gives_the_same_design(small_design, tmp_path, how) -> None:  # noqa: ANN001
    from saucerfab.errors import Interrupted

    req, reference = small_design
    out = tmp_path / "design"

    def interrupt(stage, it, max_it, parts, elapsed):  # noqa: ANN001
        if stage == "sparse":  # the second stage of the default method: the first is in the checkpoint
            if how == "KeyboardInterrupt":
                raise KeyboardInterrupt
            _as_numba_surfaces_it()

    with pytest.raises(Interrupted):
        run_design(req, out, progress=interrupt, log_every_s=0.0)
    assert not out.exists()  # no half-written design folder
    assert (tmp_path / ".design.checkpoint" / "state.npz").is_file()
    run_design(req, out, progress=lambda *a: None)
    assert not (tmp_path / ".design.checkpoint").exists()
    assert np.array_equal(np.load(out / "heights.npy"), np.load(reference / "heights.npy"))


def test_an_error_that_is_not_an_interrupt_is_not_taken_for_one(tmp_path) -> None:  # noqa: ANN001
    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", resolution=12, image_size=32,
                        max_iters=3)

    def broken(stage, it, max_it, parts, elapsed):  # noqa: ANN001
        raise SystemError("a real defect")

    with pytest.raises(SystemError, match="a real defect"):
        run_design(req, tmp_path / "d", progress=broken, log_every_s=0.0)
    assert not (tmp_path / ".d.checkpoint" / "state.npz").exists()


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


# --------------------------------------------------------------------------- issue 14: the design command

TINY = ["--resolution", "16", "--image-size", "48", "--max-iters", "5"]


def _design_argv(out: Path, *extra: str) -> list[str]:
    return ["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png"),
            *TINY, "-o", str(out), *extra]


def test_cli_design_json_short_options_and_force(tmp_path, capsys) -> None:
    out = tmp_path / "design"
    assert main(_design_argv(out, "-q", "--json")) == 0
    captured = capsys.readouterr()
    d = json.loads(captured.out)  # one JSON object and nothing else on stdout
    assert set(d) == {"design", "enhancement", "stages", "final", "verify"}
    assert d["design"] == str(out)
    assert d["enhancement"]["strategy"] == "subject"
    assert d["verify"]["schema"] == "saucerfab.verify/3"  # the quick verify of a trial export
    from saucerfab.workflow import QUICK_TEXTURE_PX

    # ... with a small atlas: the printer's own would cost a 16x larger bake for a 128 px render
    assert json.loads((out / "verify" / "verify.json").read_text())["texture_px"] == QUICK_TEXTURE_PX
    assert [s["name"] for s in d["stages"]] == ["bw_sigma_large", "sparse"]  # auto, pictures with a subject
    for st in d["stages"]:
        assert {"name", "iterations", "E_visual", "E_deform", "stop_reason", "seconds"} <= set(st)
    assert d["final"]["E_visual_final"] > 0 and d["final"]["max_abs_height_change"] >= 0
    assert "original pictures" in d["final"]["E_visual_final_against"]
    assert "it " not in captured.err  # -q: no progress lines
    # an existing design is not replaced without --force
    before = (out / "design.json").read_bytes()
    assert main(_design_argv(out)) == 2
    err = capsys.readouterr().err
    assert str(out) in err and "--force" in err
    assert (out / "design.json").read_bytes() == before
    # with --force it is; the text summary says what the final E_visual is measured against
    assert main(_design_argv(out, "--force")) == 0
    captured = capsys.readouterr()
    assert "final E_visual" in captured.out and "against the original pictures" in captured.out
    # ... and which method ran, and that it was the default's choice
    assert ("method auto (the default): bw_sigma_large, sparse (the small-sigma stage skipped: these pictures "
            "have a clear subject), at most 5 iterations a stage") in captured.out
    assert "it " in captured.err  # progress on stderr, not stdout
    # --seed says what it seeds
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    usage = " ".join(capsys.readouterr().out.split())
    assert "--seed SEED seed of the random parts of a built-in base shape" in usage


def test_cli_design_refuses_a_weight_the_ablation_does_not_use(tmp_path, capsys) -> None:
    out = tmp_path / "design"
    for ablation, option in (("no_deform", "--lam"), ("sparse_only", "--w-large"), ("laplacian_bw", "--lam")):
        assert main(_design_argv(out, "--ablation", ablation, option, "5")) == 2
        err = capsys.readouterr().err
        assert option in err and f"--ablation {ablation}" in err and "Traceback" not in err
    assert not out.exists()
    # which weights a setting uses comes from its stages
    from saucerfab.optimize.stages import weights_used

    assert weights_used("no_deform") == set()
    assert weights_used("sparse_only") == {"lam"}
    assert weights_used("laplacian") == {"w_large", "w_small"}
    assert weights_used("full", "paper") == {"w_large", "w_small", "lam"}
    assert weights_used("full", "fast") == {"w_large", "lam"}  # fast skips the small-sigma stage
    # the default, auto, skips it for enhanced pictures only; before the pictures are read, either may run
    assert weights_used("full", "auto", enhanced=True) == {"w_large", "lam"}
    assert weights_used("full", "auto", enhanced=False) == weights_used("full") == {"w_large", "w_small", "lam"}


def test_method_fast_skips_the_small_sigma_stage(tmp_path, capsys) -> None:
    from saucerfab.optimize.stages import ABLATION_STAGES, stages_for

    assert stages_for("full", "paper") == ABLATION_STAGES["full"]  # the paper's three stages
    assert stages_for("full", "fast") == [ABLATION_STAGES["full"][0], ABLATION_STAGES["full"][2]]
    # the default, auto: the small-sigma stage for pictures used as they are (photographs) only
    assert stages_for("full") == stages_for("full", "auto", enhanced=True) == stages_for("full", "fast")
    assert stages_for("full", "auto", enhanced=False) == ABLATION_STAGES["full"]
    assert stages_for("full", "fast", enhanced=False) == stages_for("full", "fast")
    assert stages_for("laplacian") == ABLATION_STAGES["laplacian"]  # and the ablations as written
    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", method="fast", **TINY_REQ)
    out = run_design(req, tmp_path / "d", progress=lambda *a: None).folder
    meta = json.loads((out / "design.json").read_text())
    assert meta["parameters"]["method"] == "fast"
    assert [s["name"] for s in meta["parameters"]["stages"]] == ["bw_sigma_large", "sparse"]
    assert [s["name"] for s in meta["metrics"]["stages"]] == ["bw_sigma_large", "sparse"]
    # contradictions are refused, naming the fix: an ablation runs as written; w_small weighs a skipped stage
    d = tmp_path / "e"
    assert main(_design_argv(d, "--ablation", "laplacian", "--method", "fast")) == 2
    err = capsys.readouterr().err
    assert "--method fast" in err and "--ablation laplacian" in err and "Traceback" not in err
    assert main(_design_argv(d, "--method", "fast", "--w-small", "5")) == 2
    err = capsys.readouterr().err
    assert "--w-small" in err and "--method fast skips" in err
    with pytest.raises(ConfigError, match="--method fast"):
        DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", method="fast", w_small=5.0)
    with pytest.raises(ConfigError, match="method must be one of auto, fast, paper"):
        DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", method="quick")
    assert not d.exists()


def test_each_method_has_its_stage_cap_and_max_iters_overrides_it(tmp_path, capsys) -> None:
    from saucerfab.optimize.stages import STAGE_CAPS, method_used, stage_cap

    assert method_used("full") == "auto" and method_used("laplacian") == "paper"  # ablations run as written
    # the default: 120 iterations a stage for pictures with a subject (two stages), 90 for photographs (three)
    assert stage_cap("full") == stage_cap("full", enhanced=True) == 120 and stage_cap("full", enhanced=False) == 90
    assert STAGE_CAPS["auto"] == (120, 90) and stage_cap("full", "fast", enhanced=False) == 120
    assert stage_cap("full", "paper") == stage_cap("sparse_only") == STAGE_CAPS["paper"][1] == 400
    assert stage_cap("full", "paper", 7) == stage_cap("full", max_iters=7) == 7  # given: every stage, any method
    # the stall rule: the default's and fast's, not the paper's (nor the ablations', which run as written)
    from saucerfab.optimize.stages import stall_window

    assert stall_window("full") == stall_window("full", "fast") == 16
    assert stall_window("full", "paper") == stall_window("laplacian") == 0
    pics = (SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png")
    assert DesignRequest(*pics).stage_cap() == 120 and DesignRequest(*pics, max_iters=500).stage_cap() == 500
    assert DesignRequest(*pics, ablation="laplacian").stage_cap() == 400  # ablations run as the paper wrote them
    for bad, why in ((0, "at least 1"), (-3, "at least 1"), (2.5, "a whole number"), (True, "a whole number"),
                     ("9", "a whole number")):
        with pytest.raises(ConfigError, match=f"max_iters must be {why}"):
            DesignRequest(*pics, max_iters=bad)
    # a weight of the stage the default skips for these pictures is refused once they are read (before any
    # stage), and the message says it is the default's choice; photographs run that stage, so it weighs it
    assert main(["design", "--direct", str(pics[0]), "--reflected", str(pics[1]), "--out",
                 str(tmp_path / "d"), "--w-small", "5", *TINY]) == 2
    err = capsys.readouterr().err
    assert "--w-small" in err and "the default method (auto), for pictures with a clear subject" in err
    assert "--method paper" in err and "Traceback" not in err
    assert not (tmp_path / "d").exists() and not (tmp_path / ".d.checkpoint").exists()
    with pytest.raises(ConfigError, match="--w-small"):  # known up front when the enhancement is asked for
        DesignRequest(*pics, enhancement="subject", w_small=5.0)
    photos = (SAMPLES / "photos" / "chelsea.png", SAMPLES / "photos" / "coffee.png")
    out = run_design(DesignRequest(*photos, w_small=5.0, **TINY_REQ), tmp_path / "p", progress=lambda *a: None).folder
    params = json.loads((out / "design.json").read_text())["parameters"]
    assert [s["name"] for s in params["stages"]] == ["plain_sigma_large", "plain_sigma_small", "sparse"]
    assert params["weights_used"]["w_small"] == 5.0 and params["max_iters_used"] == TINY_REQ["max_iters"]
    out = run_design(DesignRequest(*photos, resolution=12, image_size=32), tmp_path / "q", progress=lambda *a: None).folder
    params = json.loads((out / "design.json").read_text())["parameters"]
    assert params["max_iters_used"] == 90  # the default's cap for photographs
    assert params["stall_window_used"] == 16
    assert all(st["iterations"] <= 90 for st in json.loads((out / "design.json").read_text())["metrics"]["stages"])



def test_interrupt_in_the_first_stage_says_nothing_finished(tmp_path) -> None:
    from saucerfab.errors import Interrupted

    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png",
                        resolution=16, image_size=48, max_iters=5)

    def interrupt(stage, it, max_it, parts, elapsed):
        raise KeyboardInterrupt

    with pytest.raises(Interrupted) as info:
        run_design(req, tmp_path / "design", progress=interrupt, log_every_s=0.0)
    msg = str(info.value)
    assert "last finished stage" not in msg
    assert "no stage had finished yet" in msg and "start" in msg


def test_resumed_design_counts_the_earlier_run_and_says_so(tmp_path, capsys, monkeypatch) -> None:
    from saucerfab.optimize import pipeline

    def interrupt_second(stage, it, max_it, parts, elapsed):
        if stage == "sparse":  # the default method's second stage
            raise KeyboardInterrupt

    out = tmp_path / "design"
    monkeypatch.setattr(pipeline, "_print_progress", interrupt_second)
    assert main(_design_argv(out)) == 130
    err = capsys.readouterr().err
    assert "bw_sigma_large" in err and "last to finish" in err
    monkeypatch.undo()
    assert main(_design_argv(out)) == 0
    captured = capsys.readouterr()
    m = json.loads((out / "design.json").read_text())["metrics"]
    assert m["resumed_after_stage"] == 1
    assert m["total_s"] > m["this_run_s"] > 0  # the earlier run's finished stage counts
    assert "resumed after stage 1" in captured.out and "this run" in captured.out


# --------------------------------------------------------------------------- enhancement and frames (issue 14)

TINY_REQ = {"resolution": 16, "image_size": 48, "max_iters": 3}


def _used(folder: Path) -> tuple[dict, list[str]]:
    params = json.loads((folder / "design.json").read_text())["parameters"]
    return params["enhancement_used"], [s["name"] for s in params["stages"]]


def test_photographs_without_a_subject_are_designed_without_enhancement(tmp_path) -> None:  # noqa: ANN001
    req = DesignRequest(SAMPLES / "photos" / "chelsea.png", SAMPLES / "photos" / "coffee.png", **TINY_REQ)
    out = run_design(req, tmp_path / "d", progress=lambda *a: None).folder
    used, stages = _used(out)
    assert used["asked"] == "auto" and used["strategy"] == "none"
    assert "'chelsea.png'" in used["why"] and str(SAMPLES) not in used["why"]  # the file's name, not a path
    assert stages == ["plain_sigma_large", "plain_sigma_small", "sparse"]  # auto runs the small stage for photos
    # the paper's enhancement, asked for, still needs a subject
    with pytest.raises(ImageError, match="no foreground"):
        run_design(DesignRequest(SAMPLES / "photos" / "chelsea.png", SAMPLES / "photos" / "coffee.png",
                                 enhancement="subject", **TINY_REQ), tmp_path / "e", progress=lambda *a: None)


def test_a_photo_with_a_threshold_mask_but_no_plain_background_is_not_enhanced(tmp_path) -> None:  # noqa: ANN001
    from saucerfab.imaging import masks as im

    rocket = im.prepare_image(SAMPLES / "photos" / "rocket.jpg", 96)
    heart = im.prepare_image(SAMPLES / "direct_heart.png", 96)
    assert rocket.mask_source == "threshold" and im.plain_background_share(rocket) < im.PLAIN_SHARE
    assert im.plain_background_share(heart) > 0.95
    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "photos" / "rocket.jpg", **TINY_REQ)
    used, _ = _used(run_design(req, tmp_path / "d", progress=lambda *a: None).folder)
    assert used["strategy"] == "none" and "reflected picture 'rocket.jpg': no plain background" in used["why"]


def test_graphics_with_a_clear_subject_keep_the_papers_enhancement_and_none_is_honoured(tmp_path, capsys) -> None:  # noqa: ANN001
    args = ["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png"),
            "--resolution", "16", "--image-size", "48", "--max-iters", "3", "-q"]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    assert "black-white enhancement: every picture has a clear subject" in capsys.readouterr().out
    used, stages = _used(tmp_path / "a")
    assert used["strategy"] == "subject" and stages[0] == "bw_sigma_large"
    assert main([*args, "-o", str(tmp_path / "b"), "--enhancement", "none"]) == 0
    used, stages = _used(tmp_path / "b")
    assert used == {"asked": "none", "strategy": "none", "why": "--enhancement none was asked for"}
    assert stages[0] == "plain_sigma_large"


def test_enhancement_with_another_ablation_is_refused(capsys) -> None:  # noqa: ANN001
    rc = main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected", str(SAMPLES / "reflected_star.png"),
               "--enhancement", "none", "--ablation", "laplacian", "-o", "/nonexistent/x"])
    assert rc == 2 and "--ablation laplacian fixes its own" in capsys.readouterr().err


def test_the_default_frames_show_each_whole_picture(tmp_path) -> None:  # noqa: ANN001
    from saucerfab.model.scene import paper_scene

    assert DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png").frames == "inscribed"
    out = run_design(DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", **TINY_REQ),
                     tmp_path / "d", progress=lambda *a: None)
    assert out.folder == tmp_path / "d"  # the design returned is the one written
    scene = load_design(out.folder).scene
    assert scene == out.scene
    assert scene.direct != paper_scene().direct  # re-aimed at the saucer
    assert scene.camera == paper_scene().camera  # from the same eye
