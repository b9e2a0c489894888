"""The studio's job queue: order, discard, and a worker process that dies without a word."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest
from studio_helpers import HEART, STAR, TINY

from saucerfab.studio.jobs import Job, JobQueue
from saucerfab.studio.workspace import Workspace


def _upload(ws: Workspace, src: Path, role: str) -> str:
    fd, tmp = ws.incoming()
    with open(fd, "wb") as fh:
        fh.write(src.read_bytes())
    return ws.store_upload(tmp, role, src.name, max_pixels=64_000_000)["id"]


def test_queue_order_and_discard(tmp_path: Path) -> None:
    q = JobQueue(Workspace(tmp_path))  # not started: nothing runs
    jobs = [Job("design", "a"), Job("export", "a", "j55"), Job("design", "b")]
    for j in jobs + [jobs[0]]:  # a job queued twice is queued once
        q.submit(j)
    assert q.queued() == jobs
    assert q.discard(jobs[1]) and not q.discard(jobs[1])
    assert q.queued() == [jobs[0], jobs[2]]
    q.shutdown(timeout_s=0)
    try:
        q.submit(Job("design", "c"))
    except RuntimeError as exc:
        assert "shutting down" in str(exc)
    else:
        raise AssertionError("a queue that is shutting down took a job")


def test_a_worker_that_dies_leaves_the_run_failed_naming_its_log(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    options = {"direct": _upload(ws, HEART, "direct"), "reflected": _upload(ws, STAR, "reflected"), **TINY}
    run_id = ws.create_run(options, "t")["id"]
    q = JobQueue(ws, grace_s=5)
    q.start()
    try:
        q.submit(Job("design", run_id))
        deadline = time.monotonic() + 30
        while run_id not in q.running() and time.monotonic() < deadline:
            time.sleep(0.02)
        os.kill(q.running()[run_id], signal.SIGKILL)  # out of memory, a crash in native code...
        while ws.read_run(run_id)["status"] == "running" and time.monotonic() < deadline:
            time.sleep(0.05)
        rec = ws.read_run(run_id)
        assert rec["status"] == "failed", rec
        assert "stopped unexpectedly" in rec["error"] and f"runs/{run_id}/worker.log" in rec["error"]
    finally:
        q.shutdown()


def _long_run(ws: Workspace) -> str:
    from studio_helpers import LONG

    options = {"direct": _upload(ws, HEART, "direct"), "reflected": _upload(ws, STAR, "reflected"), **LONG}
    return ws.create_run(options, "t")["id"]


def _wait(ws: Workspace, run_id: str, until, timeout_s: float = 60) -> dict:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while True:
        rec = ws.read_run(run_id)
        prog = ws.runs / run_id / "progress.json"
        if until(rec, prog):
            return rec
        if time.monotonic() > deadline:
            raise AssertionError(f"run {run_id}: {rec}")
        time.sleep(0.05)


def _in_stage(rec: dict, prog: Path) -> bool:
    import json

    try:
        p = json.loads(prog.read_text())
        return rec["status"] == "running" and p.get("stage_index") == 0 and p.get("iteration", 0) > 0
    except (OSError, ValueError):
        return False


@pytest.mark.parametrize("sigint_ignored", [False, True], ids=["sigint-default", "sigint-ignored"])
def test_shutdown_saves_the_checkpoint_and_leaves_the_run_interrupted(tmp_path: Path, sigint_ignored: bool) -> None:
    """``sigint-ignored``: a server started in the background by a non-interactive shell (``saucerfab studio &``)
    has SIGINT ignored and its spawned workers inherit that; they must still stop on the studio's SIGINT
    (before the fix they ran to "done": CI ran the suite so)."""
    import signal

    ws = Workspace(tmp_path)
    run_id = _long_run(ws)
    q = JobQueue(ws, grace_s=20)
    old = signal.signal(signal.SIGINT, signal.SIG_IGN if sigint_ignored else signal.getsignal(signal.SIGINT))
    try:
        q.start()
        q.submit(Job("design", run_id))
        _wait(ws, run_id, _in_stage)
    finally:
        signal.signal(signal.SIGINT, old)
    q.shutdown()
    rec = ws.read_run(run_id)
    assert rec["status"] == "interrupted" and "resume" in rec["error"], (rec["status"], rec.get("error"))
    assert (ws.runs / run_id / ".design.checkpoint" / "state.npz").is_file()


def test_a_worker_stops_when_its_server_dies(tmp_path: Path) -> None:
    """The server process vanishes (os._exit): its worker notices, saves its checkpoint and records the interruption."""
    import subprocess
    import sys
    import textwrap

    ws = Workspace(tmp_path)
    run_id = _long_run(ws)
    script = textwrap.dedent(f"""
        import json, os, time
        from saucerfab.studio.jobs import Job, JobQueue
        from saucerfab.studio.workspace import Workspace
        ws = Workspace({str(ws.root)!r}, create=False)
        q = JobQueue(ws)
        q.start()
        q.submit(Job("design", {run_id!r}))
        prog = ws.runs / {run_id!r} / "progress.json"
        for _ in range(1200):
            try:
                if json.loads(prog.read_text()).get("iteration", 0) > 0:
                    break
            except (OSError, ValueError):
                pass
            time.sleep(0.05)
        os._exit(0)  # no shutdown, no signal to the worker: as if the server were killed
    """)
    subprocess.run([sys.executable, "-c", script], check=True, timeout=90)
    rec = _wait(ws, run_id, lambda r, p: r["status"] != "running", timeout_s=30)
    assert rec["status"] == "interrupted", rec
    assert (ws.runs / run_id / ".design.checkpoint" / "state.npz").is_file()
    assert "interrupted in stage" in (ws.runs / run_id / "worker.log").read_text()  # run_design saved its state


def test_the_progress_counts_the_stages_of_the_plan_that_runs(tmp_path: Path) -> None:
    """Under the default method a photograph runs three stages and a picture with a subject two: the
    progress learns which from the first stage's name (the pictures are read inside run_design)."""
    import json

    from saucerfab.optimize.request import DesignRequest
    from saucerfab.samples import SAMPLES
    from saucerfab.studio.worker import _Reporter

    class Alive:
        def gone(self) -> bool:
            return False

    def doc(folder: Path) -> dict:
        return json.loads((folder / "progress.json").read_text())

    for pics, first, names in (
        ((HEART, STAR), "bw_sigma_large", ["bw_sigma_large", "sparse"]),
        ((SAMPLES / "photos" / "chelsea.png", SAMPLES / "photos" / "coffee.png"), "plain_sigma_large",
         ["plain_sigma_large", "plain_sigma_small", "sparse"]),
    ):
        folder = tmp_path / first
        folder.mkdir()
        rep = _Reporter(folder, DesignRequest(*pics), Alive())
        for i, name in enumerate(names):
            rep.progress(name, 1, 120, {"E_visual": 1.0}, 0.1)
            d = doc(folder)
            assert (d["stage"], d["stage_index"], d["stages"]) == (name, i, len(names)), d
        assert d["max_iterations"] == 120  # the default method's cap
