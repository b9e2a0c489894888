"""Tests of the CLI's frame and its basic subcommands (``--help``, ``--version``, ``shapes``, ``scene``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import saucerfab
from saucerfab.cli import SUBCOMMANDS, main
from saucerfab.model.cups import PrismCup
from saucerfab.model.heightfield import base_shape, load_shape
from saucerfab.model.scene import Scene, default_scene, load_scene, scene_to_toml


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
    assert names == sorted(["plane", "waves", "paper_waves", "tabula_scalata", "ripples", "bowl", "smooth_random"])


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
    assert code == 0 and out == scene_to_toml(default_scene())
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


def _run_into_closed_pipe(argv: list[str]) -> tuple[int, str]:
    """Run ``python -m saucerfab ARGV`` with stdout a pipe whose reader has already gone."""
    import os
    import subprocess
    import sys

    read_end, write_end = os.pipe()
    os.close(read_end)  # every write to stdout now fails with EPIPE, as after `| head -1` has exited
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "saucerfab", *argv],
            check=False, stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=120,
        )
    finally:
        os.close(write_end)
    return proc.returncode, proc.stderr


@pytest.mark.parametrize("argv", [["check", "--schema"], ["printers"], ["--version"]])
def test_a_closed_stdout_pipe_exits_quietly(argv: list[str]) -> None:
    code, err = _run_into_closed_pipe(argv)
    assert code == 0, err
    assert "Broken pipe" not in err and "Traceback" not in err and "Exception ignored" not in err, err


def test_check_schema_into_head_exits_quietly() -> None:
    import subprocess
    import sys

    # the issue's own command line; PIPESTATUS gives saucerfab's exit code without pipefail
    script = f'"{sys.executable}" -m saucerfab check --schema | head -1; echo "saucerfab exit ${{PIPESTATUS[0]}}" >&2'
    proc = subprocess.run(["bash", "-c", script], check=False, capture_output=True, text=True, timeout=120)
    assert proc.stdout == "{\n"
    assert "Broken pipe" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "saucerfab exit 0", proc.stderr


def test_errors_still_reported_when_stdout_is_a_closed_pipe() -> None:
    code, err = _run_into_closed_pipe(["check"])  # no files: a usage error on stderr, exit 2
    assert code == 2 and "give one or more mesh files" in err and "Broken pipe" not in err


def _python_floor(requires: str) -> tuple[int, int]:
    """The lowest Python that ``requires-python`` (``>=3.11``, ``>=3.11,<4``, ``~=3.11``) admits."""
    import re

    floors = []
    for clause in requires.split(","):
        m = re.fullmatch(r"\s*(>=|~=|==|>)\s*(\d+)\.(\d+)(?:\.[\d*]+)?\s*", clause)
        if m:
            major, minor = int(m.group(2)), int(m.group(3)) + (m.group(1) == ">")
            floors.append((major, minor))
    assert floors, f"requires-python {requires!r} names no lower bound"
    return max(floors)


def test_requires_python_admits_no_python_without_tomllib() -> None:
    import re
    import tomllib

    root = Path(saucerfab.__file__).resolve().parent
    pyproject = tomllib.loads((root.parent / "pyproject.toml").read_text(encoding="utf-8"))
    floor = _python_floor(pyproject["project"]["requires-python"])
    uses = [
        str(p.relative_to(root.parent))
        for p in sorted(root.rglob("*.py"))
        if re.search(r"^\s*(import tomllib|from tomllib import)", p.read_text(encoding="utf-8"), re.MULTILINE)
    ]
    assert uses, "nothing imports tomllib any more: this test can go"
    assert floor >= (3, 11), f"requires-python lets Python {floor[0]}.{floor[1]} install, but {uses} import tomllib (3.11+)"
    assert _python_floor(">=3.10") == (3, 10) and _python_floor(">3.10,<4") == (3, 11)


@pytest.mark.parametrize(("argv", "code"), [(["printers"], 0), (["check"], 2)])
def test_the_console_entry_exits_with_the_code_and_leaves_the_collector_frozen(argv: list[str], code: int) -> None:
    """``entry()`` passes ``main``'s exit code on, and Python's shutdown after it scans no
    object of the command for cycles (0.9 s of a design's process, issue 18)."""
    import subprocess
    import sys

    script = (
        "import atexit, gc, sys\n"
        "atexit.register(lambda: print('frozen at exit:', gc.get_freeze_count() > 0))\n"
        f"sys.argv = ['saucerfab', *{argv!r}]\n"
        "from saucerfab.cli import entry\n"
        "entry()\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == code, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "frozen at exit: True", proc.stdout
