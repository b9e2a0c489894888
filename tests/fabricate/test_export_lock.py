"""One ``saucerfab export`` per ``--out`` at a time (issue 16).

An export replaces its folder whole; before the lock, a second export into
the folder while the first was checking its files removed them (the first
then reported a ``saucer.3mf`` that was gone). Now the second fails at once,
exit 2, naming the folder.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.model.design_folder import save_design, synthetic_design

#: a second process that holds an export folder's lock until killed
HOLD_THE_LOCK = """
import sys, time
from saucerfab.fabricate.pipeline import export_lock
with export_lock(sys.argv[1]):
    print("held", flush=True)
    time.sleep(120)
"""
QUICK = ["--printer", "j55", "--cup-diameter-mm", "80", "--texture-px", "64", "--no-verify", "-q"]


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_design(
        synthetic_design(resolution=16, texture_size=64, seed=1), tmp_path_factory.mktemp("d") / "design"
    )


def test_a_second_export_into_the_same_folder_fails_at_once(
    design_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Export A (3MF) is held between writing its folder and checking its files;
    export B (PLY) into the same folder meanwhile must fail fast, and leave A's
    files as A reports them."""
    from saucerfab.workflow import printing as finish

    out = tmp_path / "print"
    a_written, b_done = threading.Event(), threading.Event()
    real = finish.finish_print

    def held(result, *args, **kwargs):  # type: ignore[no-untyped-def]
        if threading.current_thread().name == "export-a":
            a_written.set()  # A's files are written; B comes now
            b_done.wait(120)
        return real(result, *args, **kwargs)

    monkeypatch.setattr(finish, "finish_print", held)
    codes: dict[str, int] = {}
    a = threading.Thread(
        target=lambda: codes.update(a=main(["export", str(design_dir), "--formats", "3mf", *QUICK, "-o", str(out)])),
        name="export-a",
    )
    a.start()
    try:
        assert a_written.wait(120), "export A did not get to its check"
        t = time.perf_counter()
        code_b = main(["export", str(design_dir), "--formats", "ply", *QUICK, "-o", str(out)])
        seconds_b = time.perf_counter() - t
    finally:
        b_done.set()
        a.join(120)
    err = capsys.readouterr().err
    assert code_b == 2, err
    assert "another saucerfab export is writing into" in err and str(out) in err and "Traceback" not in err
    assert seconds_b < 5, f"the second export took {seconds_b:.1f} s to give up; it must not wait or work"
    assert codes["a"] == 0
    assert (out / "saucer.3mf").is_file() and not (out / "saucer.ply").exists()  # A's files, as A reported
    assert not (tmp_path / ".print.export.lock").exists()  # no lock file left beside the folder
    # once A is done, the folder is free again (A's export is replaced with --force)
    assert main(["export", str(design_dir), "--formats", "ply", *QUICK, "--force", "-o", str(out)]) == 0
    assert (out / "saucer.ply").is_file()


def test_an_export_held_by_another_process(design_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "print"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_THE_LOCK, str(out)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        code = main(["export", str(design_dir), "--formats", "3mf", *QUICK, "-o", str(out)])
        err = capsys.readouterr().err
        assert code == 2 and "another saucerfab export is writing into" in err and str(out) in err, err
        assert not out.exists()
    finally:
        holder.kill()  # kill -9: the kernel frees its lock; the stale lock file blocks nobody
        holder.wait(30)
    assert main(["export", str(design_dir), "--formats", "3mf", *QUICK, "-o", str(out)]) == 0
    assert (out / "saucer.3mf").is_file() and not (tmp_path / ".print.export.lock").exists()


def test_a_bad_export_leaves_no_folder_behind(design_dir: Path, tmp_path: Path) -> None:
    """The lock lives in --out's parent, made when missing; a refused export takes it away again."""
    out = tmp_path / "new" / "deeper" / "print"
    assert main(["export", str(design_dir), "--formats", "fbx", *QUICK, "-o", str(out)]) == 2
    assert not (tmp_path / "new").exists()


def test_exclusive_lock_is_one_holder_and_removable(tmp_path: Path) -> None:
    from saucerfab.files.fileio import exclusive_lock

    lock = tmp_path / ".x.lock"

    def busy() -> ConfigError:
        return ConfigError("busy")

    # a second holder in this process is refused too (two threads, two exports)
    with exclusive_lock(lock, busy, remove=True), pytest.raises(ConfigError, match="busy"), exclusive_lock(lock, busy):
        pass
    assert not lock.exists()
    lock.write_bytes(b"")  # left by a holder killed with kill -9: no lock is held on it
    with exclusive_lock(lock, busy):
        assert lock.exists()
    assert lock.exists()  # remove=False (the batch's lock in its output folder) keeps it
    os.unlink(lock)
