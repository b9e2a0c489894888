"""Ctrl-C and SIGTERM on a batch always end it, in bounded time.

* On worker processes (or a cluster) a signal only sets a flag that the driver
  checks once a turn: a ``KeyboardInterrupt`` raised anywhere in the driver
  could land inside ``concurrent.futures``' own locking and leave a lock held
  for ever (the pool's manager thread then never ends, nor the batch).
* Stopping a pool is bounded even when its manager thread is stuck: on a lock
  nobody releases, or reading half a result from a worker killed mid-send.

The end-to-end Ctrl-C of a real batch is ``test_batch.py::test_interrupt_keeps_finished_jobs``.
"""

from __future__ import annotations

import shutil
import signal
import struct
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from saucerfab.batch import executors, run_batch
from saucerfab.batch import runner as runner_mod
from saucerfab.batch.executors import InProcessEngine, LocalPoolEngine
from saucerfab.batch.runner import _interrupts_between_jobs
from saucerfab.errors import Interrupted

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples" / "batch"


@pytest.fixture(autouse=True)
def _sigint_as_in_a_terminal():
    """SIGINT with Python's default handler, whatever this test process inherited: a suite started
    in the background (``make test &``, CI) runs with SIGINT ignored, which the batch keeps ignored."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


class _SlowPool:
    """An engine that never finishes a job; its first ``wait`` gets a SIGINT in the middle."""

    name = "fake pool"
    slots = 2
    scratch_in_output = False

    def __init__(self) -> None:
        self.waits_finished = 0
        self.interrupted_inside = False
        self.closed_with: bool | None = None

    def submit(self, payload: Any) -> object:
        return object()

    def wait(self, handles: list[Any], timeout: float) -> list[tuple[Any, Any]]:
        try:
            if self.waits_finished == 0:
                signal.raise_signal(signal.SIGINT)
            time.sleep(0.05)  # the handler runs here: a KeyboardInterrupt would be raised inside this call
        except KeyboardInterrupt:
            self.interrupted_inside = True
            raise
        self.waits_finished += 1
        if self.waits_finished > 100:  # the signal was lost: fail, do not spin for ever
            raise AssertionError("the batch did not stop after SIGINT")
        return []

    def events(self) -> list[tuple[str, str]]:
        return []

    def close(self, cancel: bool = False) -> None:
        self.closed_with = cancel


def _manifest(folder: Path) -> Path:
    shutil.copytree(SAMPLE / "designs", folder / "designs")
    text = '[defaults]\nprinter = "j55"\ncup_diameter_mm = 80\n\n[[job]]\nid = "a"\ndesign = "designs/waves"\n'
    (folder / "m.toml").write_text(text, encoding="utf-8")
    return folder / "m.toml"


def test_a_signal_stops_a_pool_batch_between_turns_not_inside_the_engine(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    engine = _SlowPool()
    monkeypatch.setattr(runner_mod, "make_engine", lambda *a, **k: engine)
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with pytest.raises(Interrupted, match="run the same command again"):
        run_batch(_manifest(tmp_path), tmp_path / "out", workers=2)
    assert not engine.interrupted_inside
    assert engine.waits_finished == 1  # stopped at the end of the turn the signal came in
    assert engine.closed_with is True  # the in-flight job cancelled
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


def test_sigterm_is_deferred_the_same_way() -> None:
    with _interrupts_between_jobs(_SlowPool()) as deferral:
        deferral.active = True
        signal.raise_signal(signal.SIGTERM)
        time.sleep(0.01)
        assert deferral.stop.is_set()


def test_a_signal_while_the_batch_plans_interrupts_at_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Planning reads and hashes every job's inputs (long for a big batch) and touches no pool:
    Ctrl-C there stops it at once, as before."""
    engine = _SlowPool()
    monkeypatch.setattr(runner_mod, "make_engine", lambda *a, **k: engine)

    def plan(*a: Any, **k: Any) -> list[Any]:
        signal.raise_signal(signal.SIGINT)
        time.sleep(0.05)  # the handler runs here
        raise AssertionError("planning went on after SIGINT")

    monkeypatch.setattr(runner_mod, "plan_batch", plan)
    with pytest.raises(Interrupted):
        run_batch(_manifest(tmp_path), tmp_path / "out", workers=2)
    assert engine.waits_finished == 0 and engine.closed_with is True


def test_in_process_jobs_are_interrupted_at_once() -> None:
    with _interrupts_between_jobs(InProcessEngine()) as deferral:
        deferral.active = True
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
            time.sleep(0.01)
        assert not deferral.stop.is_set()


def test_an_ignored_signal_stays_ignored() -> None:
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with _interrupts_between_jobs(_SlowPool()) as deferral:
            deferral.active = True
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            signal.raise_signal(signal.SIGINT)
            time.sleep(0.01)
            assert not deferral.stop.is_set()
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, old)


def test_from_another_thread_nothing_changes() -> None:
    box: dict[str, Any] = {}

    def run() -> None:
        with _interrupts_between_jobs(_SlowPool()):
            box["handler"] = signal.getsignal(signal.SIGINT)

    t = threading.Thread(target=run)
    t.start()
    t.join()
    assert box["handler"] is signal.default_int_handler


# --------------------------------------------------------------------------- stopping a pool


def _close_within(engine: LocalPoolEngine, seconds: float) -> bool:
    t = threading.Thread(target=engine.close, kwargs={"cancel": True}, daemon=True)
    t.start()
    t.join(seconds)
    return not t.is_alive()


def _running_pool(engine: LocalPoolEngine) -> tuple[Any, Any]:
    """The engine's pool with one worker busy sleeping; (pool, future)."""
    pool = engine._get_pool()
    pool.submit(time.sleep, 0).result(timeout=120)  # the worker is up
    fut = pool.submit(time.sleep, 60)
    deadline = time.monotonic() + 30
    while not fut.running() and time.monotonic() < deadline:
        time.sleep(0.01)
    return pool, fut


def test_stopping_a_pool_is_bounded_when_its_manager_thread_is_stuck(monkeypatch: pytest.MonkeyPatch) -> None:
    """A future's lock left held (as by a KeyboardInterrupt inside ``cf.wait``):
    the manager thread blocks on it when it fails the future; ``close`` returns anyway."""
    monkeypatch.setattr(executors, "STOP_JOIN_S", 1.0, raising=False)
    engine = LocalPoolEngine(1)
    pool, fut = _running_pool(engine)
    manager = pool._executor_manager_thread
    fut._condition.acquire()
    try:
        t0 = time.monotonic()
        assert _close_within(engine, 30), "close(cancel=True) did not return"
        assert time.monotonic() - t0 < 20
        assert manager.is_alive()  # still waiting for the lock
    finally:
        fut._condition.release()
    manager.join(30)
    assert not manager.is_alive()


def test_a_worker_killed_mid_send_does_not_hang_the_stop() -> None:
    """Half a result in the result pipe (a worker killed while sending): the manager
    thread, reading it, gets EOF once the driver's copy of the write end is closed."""
    engine = LocalPoolEngine(1)
    pool, fut = _running_pool(engine)
    manager = pool._executor_manager_thread
    writer = pool._result_queue._writer
    with pool._result_queue._wlock:
        # a message header promising 1 MB, and 10 bytes of it
        import os

        os.write(writer.fileno(), struct.pack("!i", 1_000_000) + b"0123456789")
    time.sleep(0.2)  # the manager thread is now inside recv(), waiting for the rest
    assert _close_within(engine, 60), "close(cancel=True) did not return"
    manager.join(10)
    assert not manager.is_alive()
    assert fut.done()
