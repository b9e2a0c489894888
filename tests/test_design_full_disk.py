"""A full disk while a design is written: the error names the path, nothing is half-written,
and the optimised state is kept so the same command finishes the design without optimising again."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

import saucerfab.optimize.pipeline as pipeline
from saucerfab.cli import main
from saucerfab.errors import OutputError
from saucerfab.files.fileio import write_bytes_atomic
from saucerfab.optimize.request import DesignRequest

SAMPLES = Path(__file__).resolve().parents[1] / "samples"
SMALL = dict(resolution=24, image_size=64, max_iters=15)


def test_a_failed_write_names_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    target = tmp_path / "a" / "b.bin"
    with pytest.raises(OSError) as exc:
        write_bytes_atomic(target, b"x" * 10)
    assert exc.value.errno == errno.ENOSPC and exc.value.filename == str(target)
    assert list(target.parent.iterdir()) == []  # no temporary file left


def test_a_full_disk_at_the_end_keeps_the_work_and_says_where(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "des"
    req = DesignRequest(SAMPLES / "direct_heart.png", SAMPLES / "reflected_star.png", **SMALL)
    real_save = pipeline.save_design

    def full_disk(design, folder, **kw):  # type: ignore[no-untyped-def]
        raise OSError(errno.ENOSPC, "No space left on device", str(Path(folder) / "texture.png"))

    monkeypatch.setattr(pipeline, "save_design", full_disk)
    with pytest.raises(OutputError) as exc:
        pipeline.optimize_design(req, out, progress=lambda *a: None)
    msg = str(exc.value)
    assert "No space left on device" in msg and str(out) in msg and ".des.checkpoint" in msg
    assert not out.exists()
    assert (tmp_path / ".des.checkpoint" / "state.npz").is_file()  # the optimised state is kept
    # with space again, the same request finishes from the checkpoint without optimising
    monkeypatch.setattr(pipeline, "save_design", real_save)
    stages_run: list[str] = []
    pipeline.optimize_design(req, out, progress=lambda stage, *a: stages_run.append(stage))
    assert (out / "design.json").is_file() and not (tmp_path / ".des.checkpoint").exists()
    assert stages_run == []  # no stage ran again
    # the CLI says it as an error with exit 2, not a traceback
    monkeypatch.setattr(pipeline, "save_design", full_disk)
    rc = main(["design", "--direct", str(SAMPLES / "direct_heart.png"), "--reflected",
               str(SAMPLES / "reflected_star.png"), "-o", str(tmp_path / "d2"), "--resolution", "24",
               "--image-size", "64", "--max-iters", "15", "--no-verify", "-q"])
    assert rc == 2 and "No space left on device" in capsys.readouterr().err
