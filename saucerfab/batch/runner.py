"""The batch driver: plan (what is already complete), run the rest on an engine, report.

The driver alone writes into the output folder ``OUT``:

* ``OUT/<job id>/`` per job, written atomically (built under a hidden
  temporary name, renamed when complete) with ``job.json`` (the completion
  marker holding the job key) written last inside it;
* ``OUT/batch-report.json`` and ``OUT/batch-report.html``, rewritten
  atomically as jobs finish;
* ``OUT/.saucerfab-batch.lock`` (one batch per output folder at a time) and
  ``OUT/.batch-tmp/`` (scratch folders of local workers).

Killed at any moment, a batch leaves only complete job folders (plus hidden
temporaries, which the next run removes), and every job that finished before
the kill is found complete by the next run and not run again.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import threading
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from saucerfab.batch.executors import WORKER_DIED, make_engine
from saucerfab.batch.jobs import (
    JobResult,
    commit,
    completed,
    failed_result,
    load_payload,
    result_from_marker,
)
from saucerfab.batch.manifest import LOCK_NAME, SCRATCH_NAME, JobSpec, Manifest, load_manifest
from saucerfab.batch.report import (
    BatchResult,
    JobOutcome,
    NullDisplay,
    report_dict,
    write_reports,
)
from saucerfab.errors import ConfigError, Interrupted, SaucerfabError
from saucerfab.files.fileio import exclusive_lock

#: how often a job may be started again after its worker process died under it
MAX_ATTEMPTS = 2


@contextlib.contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``out`` (one batch per output folder); freed even on kill -9.

    The lock file stays in ``out`` (which a batch never replaces); see
    :func:`saucerfab.files.fileio.exclusive_lock`.
    """

    def busy() -> ConfigError:
        return ConfigError(
            f"another saucerfab batch is writing into {str(out)!r}; wait for it to finish "
            "or give another --out"
        )

    with exclusive_lock(out / LOCK_NAME, busy):
        yield


class _Deferral:
    """Where a batch's Ctrl-C goes (:func:`_interrupts_between_jobs`): ``stop`` is set
    by a signal once ``active`` (jobs are in the engine's hands); before that a
    signal interrupts at once, as it always did (planning only reads files)."""

    def __init__(self) -> None:
        self.stop = threading.Event()
        self.active = False


@contextlib.contextmanager
def _interrupts_between_jobs(engine: Any) -> Iterator[_Deferral]:
    """While a batch's jobs run on worker processes or a cluster, SIGINT and SIGTERM
    only set the flag this yields (once :func:`_drive` makes it ``active``, as its
    jobs start); :func:`_drive` stops the batch at its next turn (within a
    quarter of a second, or once the job it is writing is written).

    Why: a ``KeyboardInterrupt`` raised at an arbitrary point of the driver can
    land inside ``concurrent.futures``' own bookkeeping (``wait`` takes every
    future's lock in a Python loop; ``submit`` registers a job in two steps),
    leaving a lock held by a frame that is gone: the pool's manager thread
    then waits on it forever and the batch never exits. With the in-process
    engine a job runs in this thread for minutes, so there nothing changes
    (Ctrl-C interrupts at once). A signal the process was started ignoring
    stays ignored. Handlers can be set from the main thread only; from
    another thread nothing changes either. The previous handlers
    are restored on exit, so a second Ctrl-C during the clean-up interrupts it.
    """
    deferral = _Deferral()
    if getattr(engine, "runs_jobs_here", False) or threading.current_thread() is not threading.main_thread():
        yield deferral
        return

    def handler(signum: int, frame: Any) -> None:
        if not deferral.active:
            raise KeyboardInterrupt
        deferral.stop.set()

    # a signal the process was started ignoring (``nohup``, ``cmd &``) stays ignored
    saved = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)
             if signal.getsignal(sig) is not signal.SIG_IGN}
    try:
        yield deferral
    finally:
        for sig, old in saved.items():
            if old is not None:  # None: a handler not set from Python, which cannot be put back
                signal.signal(sig, old)


def clean_stale(out: Path) -> list[Path]:
    """Remove what a killed batch may have left in ``out``: hidden ``*.part`` / ``*.old``
    temporaries of atomic writes and the workers' scratch folder. Returns what went."""
    gone = []
    for p in out.iterdir():
        if p.name == SCRATCH_NAME or (p.name.startswith(".") and p.name.endswith((".part", ".old"))):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                with contextlib.suppress(FileNotFoundError):
                    p.unlink()
            gone.append(p)
    return gone


@dataclass
class PlannedJob:
    """A job and what the planner found: ``action`` is ``reuse``, ``run`` or ``failed``."""

    job: JobSpec
    action: str
    key: str = ""
    result: JobResult | None = None


def plan_batch(manifest: Manifest, out: Path, *, force: bool = False) -> list[PlannedJob]:
    """For every job: its key, and whether its output is complete for that key.

    Reads (and hashes) every job's inputs; a job whose inputs cannot be read is
    ``failed`` at the ``inputs`` stage.
    """
    plan = []
    for job in manifest.jobs:
        try:
            key = load_payload(job, manifest.root).key
        except SaucerfabError as exc:
            plan.append(PlannedJob(job, "failed", result=failed_result(job, "inputs", str(exc))))
            continue
        marker = None if force else completed(out, job.id, key)
        if marker is not None:
            plan.append(PlannedJob(job, "reuse", key, result_from_marker(marker)))
        else:
            plan.append(PlannedJob(job, "run", key))
    return plan


def _apply(outcome: JobOutcome, result: JobResult, *, reused: bool) -> None:
    outcome.status = result.status
    outcome.reused = reused
    outcome.stage = result.stage
    outcome.reason = result.reason
    outcome.verdict = result.verdict
    outcome.checks = result.checks
    outcome.key = result.key
    outcome.trace = result.trace
    if not reused:
        outcome.times = dict(result.times)
        outcome.worker = result.worker
    outcome.output = outcome.id


def run_batch(
    manifest: Manifest | str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    force: bool = False,
    threads_per_job: int = 1,
    display: Any = None,
    report_every_s: float = 1.0,
) -> BatchResult:
    """Run every job of ``manifest`` into ``out``; skip the ones already complete.

    Args:
        manifest: a :class:`Manifest` or the path of a manifest file.
        out: the output folder (created): one folder per job plus the reports.
        workers: local worker processes; 0 runs the jobs in this process.
        scheduler: ``tcp://HOST:PORT`` of a Dask distributed scheduler to run on
            instead of local processes.
        force: run every job even if its output is complete.
        threads_per_job: compute threads each job uses (torch, BLAS).
        display: progress display (``RichDisplay``, ``LineDisplay``...; default none).

    Returns:
        The outcomes; ``.exit_code`` is 0 when every job is ok.

    Raises:
        ConfigError: bad manifest, unreachable scheduler, output folder in use.
        Interrupted: Ctrl-C or SIGTERM (finished jobs are kept; the report says which).
    """
    if not isinstance(manifest, Manifest):
        manifest = load_manifest(manifest)
    if workers < 0:
        raise ConfigError(f"--workers must be 0 (this process) or more, got {workers}")
    if threads_per_job < 1:
        raise ConfigError(f"--threads-per-job must be at least 1, got {threads_per_job}")
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    display = display or NullDisplay()
    started = time.time()
    t0 = time.perf_counter()
    outcomes = {j.id: JobOutcome(j.id, j.kind) for j in manifest.jobs}
    ordered = [outcomes[j.id] for j in manifest.jobs]
    state = {"name": "running", "last": 0.0}
    engine_name = f"Dask cluster {scheduler}" if scheduler else (
        "in this process" if workers == 0 else f"local process pool, {workers} worker{'s' * (workers != 1)}"
    )

    def report(final: bool = False) -> None:
        now = time.monotonic()
        if not final and now - state["last"] < report_every_s:
            return
        state["last"] = now
        data = report_dict(
            ordered,
            manifest=manifest.path,
            out=out,
            engine=engine_name,
            started=started,
            finished=time.time() if final else None,
            state=state["name"],
        )
        write_reports(data, out)

    with _locked(out):
        clean_stale(out)
        engine = make_engine(workers, scheduler, threads=threads_per_job)
        engine_name = engine.name
        try:
            with _interrupts_between_jobs(engine) as deferral:
                _drive(manifest, out, engine, outcomes, display, force, threads_per_job, report, deferral)
        except (KeyboardInterrupt, Interrupted):  # Ctrl-C, SIGTERM, or a stage's own Interrupted
            state["name"] = "interrupted"
            engine.close(cancel=True)
            display.close()
            report(final=True)
            clean_stale(out)  # the stopped workers' scratch folders
            done = sum(o.status != "pending" for o in ordered)
            raise Interrupted(
                f"batch interrupted: {done} of {len(ordered)} jobs are done and kept in {str(out)!r}; "
                "run the same command again to finish the rest"
            ) from None
        except BaseException:
            state["name"] = "interrupted"
            engine.close(cancel=True)
            display.close()
            report(final=True)
            clean_stale(out)  # the stopped workers' scratch folders
            raise
        engine.close()
        display.close()
        state["name"] = "finished"
        report(final=True)
        clean_stale(out)
    return BatchResult(out=out, outcomes=ordered, engine=engine_name, wall_s=time.perf_counter() - t0)


def _drive(
    manifest: Manifest,
    out: Path,
    engine: Any,
    outcomes: dict[str, JobOutcome],
    display: Any,
    force: bool,
    threads_per_job: int,
    report: Any,
    deferral: _Deferral | None = None,
) -> None:
    """Plan, then keep ``engine.slots`` jobs in flight until all are done; commit each result.

    ``deferral``: made ``active`` once the plan is made (from then on a signal
    only sets its ``stop``, :func:`_interrupts_between_jobs`); ``stop`` is
    checked once a turn, where it raises ``KeyboardInterrupt`` (the caller's
    Ctrl-C path).
    """
    plan = plan_batch(manifest, out, force=force)
    todo: deque[tuple[JobSpec, int]] = deque()
    early: list[JobOutcome] = []
    for p in plan:
        o = outcomes[p.job.id]
        assert p.result is not None or p.action == "run"
        if p.action == "reuse":
            _apply(o, p.result, reused=True)  # type: ignore[arg-type]
            o.files = _listed_files(out, p.job.id)
        elif p.action == "failed":
            commit(p.result, out)  # type: ignore[arg-type]
            _finish(o, p.result, 0, None)  # type: ignore[arg-type]
            early.append(o)
        else:
            todo.append((p.job, 1))
    # Longest first: raw-input jobs (design + export + check) start before the
    # design-folder jobs (export + check), so no worker is left with a long
    # design at the end while the others idle. The report keeps manifest order.
    todo = deque(sorted(todo, key=lambda item: item[0].kind != "raw"))
    display.start(len(plan), sum(o.reused for o in outcomes.values()))
    for o in early:
        display.done(o)
    report(final=True)
    scratch = out / SCRATCH_NAME if engine.scratch_in_output else None
    inflight: dict[Any, tuple[JobSpec, int]] = {}
    if deferral is not None:
        deferral.active = True  # jobs go to the engine from here: a signal waits for the end of a turn
    while todo or inflight:
        while todo and len(inflight) < engine.slots:
            job, attempt = todo.popleft()
            try:
                payload = load_payload(job, manifest.root, scratch_root=scratch, threads=threads_per_job)
            except SaucerfabError as exc:
                result = failed_result(job, "inputs", str(exc))
                commit(result, out)
                _finish(outcomes[job.id], result, attempt, display)
                continue
            inflight[engine.submit(payload)] = (job, attempt)
            display.queued(job.id)
        for job_id, stage in engine.events():
            display.stage(job_id, stage)
        for handle, res in engine.wait(list(inflight), timeout=0.25):
            job, attempt = inflight.pop(handle)
            if res == WORKER_DIED and attempt < MAX_ATTEMPTS:
                display.note(f"{job.id}: its worker process died; starting it again")
                todo.appendleft((job, attempt + 1))
                continue
            if res == WORKER_DIED:
                res = failed_result(
                    job,
                    "worker",
                    f"the worker process died while running this job, {attempt} times "
                    "(killed, or out of memory?); rerun the batch to try again",
                )
            elif isinstance(res, str):
                res = failed_result(job, "worker", res)
            commit(res, out)
            _finish(outcomes[job.id], res, attempt, display)
            report()
        for job_id, stage in engine.events():
            display.stage(job_id, stage)
        if deferral is not None and deferral.stop.is_set():
            raise KeyboardInterrupt


def _listed_files(out: Path, job_id: str) -> list[str]:
    from saucerfab.batch.jobs import read_marker

    marker = read_marker(out / job_id) or {}
    return sorted(marker.get("files") or {})


def _finish(outcome: JobOutcome, result: JobResult, attempt: int, display: Any) -> None:
    _apply(outcome, result, reused=False)
    outcome.attempts = attempt
    outcome.files = sorted(result.files)
    if display is not None:
        display.done(outcome)
