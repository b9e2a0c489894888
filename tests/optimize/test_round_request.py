"""A round saucer's diameter at the request and the command line (issue 44): ``--saucer-diameter-mm``.

The request takes ``saucer_diameter_mm``; the scene built from it
(:func:`saucerfab.optimize.prepare.build_scene`) has its disc rebuilt at that
diameter. A rectangle scene refuses it, and a disc too small for the cup is
refused with the scene's own message, before any work: these tests stop there,
or run a design of a second or two.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from saucerfab.cli import main
from saucerfab.errors import ConfigError, GeometryError
from saucerfab.model.scene import (
    CUP_RING_MM,
    MIN_DISC_BAND_MM,
    PRESETS,
    load_scene,
    round_grid,
    round_scene,
)
from saucerfab.optimize.prepare import build_scene
from saucerfab.optimize.request import DesignRequest

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
PAIR = {"direct": SAMPLES / "direct_heart.png", "reflected": SAMPLES / "reflected_star.png"}
#: a design of a second or two
TINY = ["--resolution", "40", "--image-size", "64", "--max-iters", "2", "--no-verify", "-q"]


def _diameter_mm(scene) -> float:  # type: ignore[no-untyped-def]
    return 2.0 * scene.saucer.radius * scene.mm_per_unit


def _smallest_mm(cup_mm: float) -> int:
    """The smallest disc around a circle cup ``cup_mm`` wide (the scene's rule, for the test's numbers)."""
    return math.ceil(cup_mm + 2.0 * (CUP_RING_MM + MIN_DISC_BAND_MM))


def test_the_round_scene_is_rebuilt_at_the_diameter_asked_for() -> None:
    scene = build_scene(DesignRequest(**PAIR, scene="round", saucer_diameter_mm=180))
    assert scene.saucer.is_disc and _diameter_mm(scene) == pytest.approx(180.0)
    assert scene.saucer.resolution == round_grid(2.0 * scene.saucer.radius)  # the grid follows the diameter
    assert scene.saucer.x_range == scene.saucer.y_range and scene.saucer.delta == round_scene().saucer.delta
    # a given resolution wins; the cup's diameter sets the scale, the saucer's stays in mm
    scene = build_scene(DesignRequest(**PAIR, scene="round", saucer_diameter_mm=180, resolution=48,
                                      cup_diameter_mm=60.0))
    assert scene.saucer.resolution == 48 and scene.cup_diameter_mm == 60.0
    assert _diameter_mm(scene) == pytest.approx(180.0)
    # left out: the scene's own disc, as before the option
    assert build_scene(DesignRequest(**PAIR, scene="round")) == round_scene()


def test_a_cup_override_and_a_larger_disc_are_applied_together() -> None:
    """A cup too big for the preset's disc fits the disc asked for: the disc is not checked in between."""
    cup = f"circle:{0.9 * round_scene().saucer.radius:g}"  # nearly the preset's whole disc, in model units
    with pytest.raises(GeometryError):
        build_scene(DesignRequest(**PAIR, scene="round", cup=cup))
    scene = build_scene(DesignRequest(**PAIR, scene="round", cup=cup, saucer_diameter_mm=200))
    assert _diameter_mm(scene) == pytest.approx(200.0) and scene.cup.width_units > round_scene().saucer.radius


@pytest.mark.parametrize("scene", [name for name, make in PRESETS.items() if not make().saucer.is_disc])
def test_a_rectangle_scene_refuses_a_saucer_diameter(scene: str) -> None:
    with pytest.raises(ConfigError, match=r"^--saucer-diameter-mm is for a round saucer: add --scene round"):
        build_scene(DesignRequest(**PAIR, scene=scene, saucer_diameter_mm=180))


def test_a_disc_too_small_for_the_cup_names_the_smallest() -> None:
    smallest = _smallest_mm(round_scene().cup_diameter_mm)
    with pytest.raises(GeometryError, match=rf"at least {smallest} mm \(--saucer-diameter-mm\)"):
        build_scene(DesignRequest(**PAIR, scene="round", saucer_diameter_mm=smallest - 5))
    build_scene(DesignRequest(**PAIR, scene="round", saucer_diameter_mm=smallest))  # the smallest itself fits


@pytest.mark.parametrize("bad", [0, -10.0, float("nan"), float("inf"), True, "180"])
def test_the_request_refuses_a_diameter_that_is_no_size(bad: object) -> None:
    with pytest.raises(ConfigError, match="saucer_diameter_mm must be a positive number of millimetres"):
        DesignRequest(**PAIR, scene="round", saucer_diameter_mm=bad)  # type: ignore[arg-type]


def test_the_option_has_one_default() -> None:
    assert DesignRequest.default("saucer_diameter_mm") is None  # None: the scene's


# --------------------------------------------------------------------------- the command line


def _design(tmp_path: Path, *args: str) -> list[str]:
    return ["design", "--direct", str(PAIR["direct"]), "--reflected", str(PAIR["reflected"]),
            "-o", str(tmp_path / "d"), *args, *TINY]


def test_cli_refuses_the_diameter_with_a_rectangle_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(_design(tmp_path, "--saucer-diameter-mm", "180")) == 2  # the default scene: the paper's rectangle
    err = capsys.readouterr().err
    assert "--saucer-diameter-mm is for a round saucer: add --scene round" in err and "Traceback" not in err
    assert not (tmp_path / "d").exists()  # refused before the design folder was started
    assert main(_design(tmp_path, "--scene", "wide", "--saucer-diameter-mm", "180")) == 2
    assert "add --scene round" in capsys.readouterr().err


def test_cli_refuses_a_disc_too_small_with_the_scenes_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    smallest = _smallest_mm(round_scene().cup_diameter_mm)
    assert main(_design(tmp_path, "--scene", "round", "--saucer-diameter-mm", "100")) == 2
    err = capsys.readouterr().err
    assert f"give a saucer of at least {smallest} mm (--saucer-diameter-mm)" in err, err
    assert not (tmp_path / "d").exists()


def test_cli_designs_on_the_disc_asked_for_and_records_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(_design(tmp_path, "--scene", "round", "--saucer-diameter-mm", "150", "--no-times")) == 0
    doc = json.loads((tmp_path / "d" / "design.json").read_text())
    assert doc["parameters"]["saucer_diameter_mm"] == 150.0 and doc["parameters"]["scene"] == "round"
    saucer = doc["scene"]["saucer"]
    assert saucer["outline"] == "disc" and saucer["resolution"] == 40
    mm_per_unit = doc["scene"]["cup_diameter_mm"] / (2 * doc["scene"]["cup"]["radius"])
    assert (saucer["x_range"][1] - saucer["x_range"][0]) * mm_per_unit == pytest.approx(150.0)


def test_cli_help_names_the_option_and_the_presets(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--saucer-diameter-mm D" in out and f"{_diameter_mm(round_scene()):g} for the round scene's" in out
    assert all(name in out for name in PRESETS)


# --------------------------------------------------------------------------- saucerfab scene


def test_scene_round_prints_toml_that_reads_back_to_the_preset(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scene", "round"]) == 0
    text = capsys.readouterr().out
    assert 'outline = "disc"' in text
    path = tmp_path / "round.toml"
    path.write_text(text, encoding="utf-8")
    assert load_scene(path) == round_scene()


def test_scene_help_lists_the_presets_with_their_saucers(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["scene", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    for name in PRESETS:
        assert f"{name} (a " in out, (name, out)
    assert f"round (a {_diameter_mm(round_scene()):g} mm round saucer, the cup at its centre)" in out, out


def test_the_round_scenes_own_disc_shrinks_to_the_printers_build_area() -> None:
    """The `round` scene's 200 mm disc for a printer whose build area is 190 mm deep: 190 mm, said in a note;
    a diameter the user gives is not changed but refused, naming the largest."""
    from saucerfab.optimize.prepare import prepare

    prep = prepare(DesignRequest(**PAIR, scene="round", printer="hp_jf580", resolution=40, image_size=32))
    assert _diameter_mm(prep.scene) == pytest.approx(190.0)
    assert any("190 mm across, the largest" in n for n in prep.print_notes), prep.print_notes
    assert _diameter_mm(prepare(DesignRequest(**PAIR, scene="round", resolution=40, image_size=32)).scene) == \
        pytest.approx(200.0)  # the J55 takes the scene's own
    with pytest.raises(ConfigError, match="--saucer-diameter-mm 190 or less"):
        prepare(DesignRequest(**PAIR, scene="round", printer="hp_jf580", saucer_diameter_mm=200.0, resolution=40,
                              image_size=32))
