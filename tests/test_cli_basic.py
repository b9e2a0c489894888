"""Tests of the CLI's frame and its basic subcommands (``--help``, ``--version``, ``shapes``, ``scene``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import saucerfab
from saucerfab.cli import SUBCOMMANDS, main
from saucerfab.heightfield import base_shape, load_shape
from saucerfab.scene import PrismCup, Scene, load_scene, paper_scene, scene_to_toml


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run ``main(argv)``; argparse's own exits count as return codes."""
    try:
        code = main(argv)
    except SystemExit as exc:  # --help, --version and usage errors exit from argparse
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def assert_clean_error(code: int, err: str, *needles: str) -> None:
    assert code == 2
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, f"{needle!r} not in {err!r}"


def test_help_lists_the_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(["--help"], capsys)
    assert code == 0
    assert "usage: saucerfab" in out
    present = [n for n, mod in SUBCOMMANDS.items() if importlib.util.find_spec(f"saucerfab.cli.{mod}")]
    assert {"shapes", "scene", "printers"} <= set(present)
    for name in present:
        assert f"    {name}" in out, f"subcommand {name} missing from --help"
    # no arguments: the same help, exit 0
    code, out2, _ = run_cli([], capsys)
    assert code == 0 and "COMMAND" in out2


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(["--version"], capsys)
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == f"saucerfab {saucerfab.__version__}"
    assert lines[1].startswith("Python 3.")
    assert lines[2].startswith("torch ")
    assert lines[3].startswith("device ") and ("CPU" in lines[3] or "GPU" in lines[3])


def test_shapes_lists_all(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(["shapes"], capsys)
    assert code == 0
    names = [line.split()[0] for line in out.splitlines()]
    assert names == sorted(["plane", "waves", "tabula_scalata", "ripples", "bowl", "smooth_random"])


def test_shapes_writes_npy_and_png_that_load_back(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    npy, png = tmp_path / "w.npy", tmp_path / "w.png"
    code, out, _ = run_cli(["shapes", "waves", "--resolution", "20", "--out", str(npy)], capsys)
    assert code == 0 and f"wrote {npy}" in out
    np.testing.assert_array_equal(np.load(npy), base_shape("waves", 20))
    code, _, _ = run_cli(["shapes", "smooth_random", "--resolution", "20", "--seed", "4", "--out", str(png)], capsys)
    assert code == 0
    # the 16-bit PNG (white = 0.1 model units) reads back to within one grey level
    back = load_shape(png, 20, height_scale=0.1)
    np.testing.assert_allclose(back, base_shape("smooth_random", 20, seed=4), atol=0.1 / 65535)


@pytest.mark.parametrize(
    "argv, needles",
    [
        (["shapes", "volcano", "--out", "x.npy"], ["saucerfab shapes: error:", "unknown base shape 'volcano'"]),
        (["shapes", "waves", "--out", "x.txt"], ["must end in .npy or .png"]),
        (["shapes", "waves"], ["give --out"]),
        (["shapes", "waves", "--resolution", "-5", "--out", "x.npy"], ["--resolution -5 is out of range"]),
        (["scene", "missing.toml"], ["saucerfab scene: error:", "not found"]),
    ],
)
def test_user_errors_exit_2_without_traceback(
    argv: list[str], needles: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(argv, capsys)
    assert_clean_error(code, err, *needles)
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["frobnicate"], capsys)
    assert_clean_error(code, err, "invalid choice")
    code, _, err = run_cli(["shapes", "--resolution", "many"], capsys)
    assert_clean_error(code, err, "invalid int value")


def test_scene_prints_and_writes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(["scene"], capsys)
    assert code == 0 and out == scene_to_toml(paper_scene())
    src = tmp_path / "in.toml"
    src.write_text('[cup]\nshape = "prism"\nsides = 6\n')
    dst = tmp_path / "out" / "scene.toml"
    code, out, _ = run_cli(["scene", str(src), "--out", str(dst)], capsys)
    assert code == 0 and f"wrote {dst}" in out
    assert load_scene(dst) == Scene(cup=PrismCup(6))


def test_scene_geometry_and_config_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    inside = tmp_path / "inside.toml"
    inside.write_text("camera = [0.0, 0.1, 2.0]\n")
    code, _, err = run_cli(["scene", str(inside)], capsys)
    assert_clean_error(code, err, "inside the cup")
    typo = tmp_path / "typo.toml"
    typo.write_text("[saucer]\nresolutoin = 64\n")
    code, _, err = run_cli(["scene", str(typo)], capsys)
    assert_clean_error(code, err, "resolutoin")


def test_ctrl_c_exits_130(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    import saucerfab.cli.scene as scene_cmd

    def interrupted(args):  # type: ignore[no-untyped-def]
        raise KeyboardInterrupt

    monkeypatch.setattr(scene_cmd, "run", interrupted)
    code, _, err = run_cli(["scene"], capsys)
    assert code == 130 and "interrupted" in err and "Traceback" not in err
