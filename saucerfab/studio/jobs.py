"""The studio's job queue: designs and exports in worker processes, at most ``jobs`` at once.

A scheduler thread in the server process (never its event loop) starts
queued jobs as worker processes (``multiprocessing`` spawn context: a fresh
interpreter, no state shared with the server; each one imports torch, about
2-3 s), or as tasks on a Dask cluster (:mod:`saucerfab.studio.cluster`,
``--scheduler``), and watches them.

Fair sharing (issue 39): every job belongs to a user, and the users take
turns: the next job to start is the oldest one of the user whose last start
is the longest ago (a user who has not started anything yet comes first).
So one designer's ten queued runs do not hold back another's one. A user
may have at most ``max_queued`` designs waiting (:meth:`JobQueue.check_room`).
:meth:`JobQueue.position` tells a queued job its place in that order.

Workers:

* cancel: the worker gets SIGINT (its ``run_design`` saves the checkpoint and
  stops); one still alive after :data:`GRACE_S` seconds is killed;
* a worker that dies without recording its end (killed, out of memory, a
  crash in native code) leaves the run ``failed`` with a message that names
  its ``worker.log``;
* shutdown: no new job starts, every running worker gets SIGINT and is waited
  for (so its checkpoint is saved: the run shows ``interrupted`` and resumes later).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from saucerfab.studio.workspace import SHARED_USER, NotFound, TooMany, Workspace, now_iso

#: seconds a worker has after SIGINT to save its checkpoint and stop, before it is killed
GRACE_S = 20.0
#: jobs run at once by default (a design already uses every core)
DEFAULT_JOBS = 1
#: how often the scheduler looks at its workers, seconds
POLL_S = 0.1
#: designs one user may have waiting in the queue by default (``--max-queued-per-user``; 0: no limit)
DEFAULT_MAX_QUEUED_PER_USER = 4


@dataclass(frozen=True)
class Job:
    """One unit of work: a run's design, its export for one printer, or that export seen under the room light."""

    kind: str  # "design", "export", or "lit" (an export seen under the room light: saucerfab.studio.lit)
    run_id: str
    printer: str | None = None


def job_entry(rec: dict[str, Any], job: Job) -> dict[str, Any] | None:
    """The part of a run's record an export or lit job reports in: the export's entry, or its ``lit``."""
    e = rec.get("exports", {}).get(job.printer or "")
    if job.kind == "lit":
        e = e.get("lit") if isinstance(e, dict) else None
    return e if isinstance(e, dict) else None


@dataclass(frozen=True)
class _Waiting:
    job: Job
    user: str
    seq: int  # the order of submission


class LocalWorker:
    """A job's worker process on this machine (``multiprocessing`` spawn context).

    The queue talks to a worker through this small interface (``start``,
    ``is_alive``, ``interrupt``, ``kill``, ``join``, ``pid``, ``ended_why``), which
    :class:`saucerfab.studio.cluster.DaskWorker` has too.
    """

    def __init__(self, ctx: Any, root: str, job: Job) -> None:
        from saucerfab.studio import worker

        self.process = ctx.Process(target=worker.main, args=(root, job.kind, job.run_id, job.printer),
                                   name=f"saucerfab-studio-{job.kind}-{job.run_id}")

    @property
    def pid(self) -> int | None:
        return self.process.pid

    def start(self) -> None:
        self.process.start()

    def is_alive(self) -> bool:
        return bool(self.process.is_alive())

    def interrupt(self) -> None:
        """SIGINT: run_design saves its checkpoint and stops."""
        if self.process.pid is not None:
            try:
                os.kill(self.process.pid, signal.SIGINT)
            except ProcessLookupError:
                pass

    def kill(self) -> None:
        self.process.kill()

    def join(self, timeout: float | None = None) -> None:
        self.process.join(timeout=timeout)

    def ended_why(self) -> str:
        """How the process ended, in words for a run's error ("exit code 1", "killed by signal 9")."""
        code = self.process.exitcode
        return f"killed by signal {-code}" if code is not None and code < 0 else f"exit code {code}"


@dataclass
class _Running:
    job: Job
    process: Any  # LocalWorker, or cluster.DaskWorker
    stop_sent: float | None = None  # perf_counter of the SIGINT, when one was sent
    killed: bool = False
    extra: dict[str, Any] = field(default_factory=dict)


class JobQueue:
    """Queued jobs and their worker processes (see the module docstring).

    Args:
        ws: the workspace.
        jobs: how many workers run at once (a design uses every core: 1 is usual).
        grace_s: seconds between SIGINT and kill.
        max_queued: designs one user may have waiting (0: no limit).
        cluster: a :class:`saucerfab.studio.cluster.DaskCluster` to run the jobs on
            (``--scheduler``); None: worker processes on this machine. On a cluster
            the jobs at once are its threads, not ``jobs``.
    """

    def __init__(self, ws: Workspace, *, jobs: int = DEFAULT_JOBS, grace_s: float = GRACE_S,
                 max_queued: int = DEFAULT_MAX_QUEUED_PER_USER, cluster: Any = None) -> None:
        if jobs < 1:
            raise ValueError(f"jobs must be at least 1, got {jobs}")
        if max_queued < 0:
            raise ValueError(f"max_queued must be 0 (no limit) or more, got {max_queued}")
        self.ws = ws
        self.jobs = jobs
        self.grace_s = grace_s
        self.max_queued = max_queued
        self.cluster = cluster
        self._pending: list[_Waiting] = []  # in the order of submission
        self._seq = 0
        self._tick = 0
        self._served: dict[str, int] = {}  # user -> the tick of their last start (round-robin)
        self._running: dict[Job, _Running] = {}
        self._stop_asked: set[str] = set()  # run ids whose design worker is to get SIGINT
        self._cond = threading.Condition()
        self._accepting = True
        self._quit = False
        self._thread: threading.Thread | None = None
        self._ctx = multiprocessing.get_context("spawn")

    # ------------------------------------------------------------------ the API's side

    def start(self) -> None:
        """Start the scheduler thread."""
        self._thread = threading.Thread(target=self._loop, name="studio-jobs", daemon=True)
        self._thread.start()

    def submit(self, job: Job, user: str = SHARED_USER) -> None:
        """Queue ``job`` of ``user`` (its turn comes as :meth:`order` says).

        Raises:
            RuntimeError: the queue is shutting down.
        """
        with self._cond:
            if not self._accepting:
                raise RuntimeError("the studio is shutting down; no new jobs are started")
            # a job whose previous worker is still ending (a resume right after a cancel) is queued too:
            # the scheduler starts it once that worker is gone
            if all(w.job != job for w in self._pending):
                self._seq += 1
                self._pending.append(_Waiting(job, user, self._seq))
            self._cond.notify_all()

    def check_room(self, user: str) -> None:
        """Whether ``user`` may queue one more design.

        Raises:
            TooMany: the user has ``max_queued`` designs waiting already (429).
        """
        if not self.max_queued:
            return
        with self._cond:
            waiting = sum(1 for w in self._pending if w.user == user and w.job.kind == "design")
        if waiting >= self.max_queued:
            raise TooMany(
                f"you have {waiting} designs waiting in the queue, the most one designer may have "
                f"(--max-queued-per-user {self.max_queued}); wait until one of them starts, or cancel one, "
                "then start this one again"
            )

    def discard(self, job: Job) -> bool:
        """Take a queued ``job`` off the queue; False when it is not queued (started, or unknown)."""
        with self._cond:
            for w in self._pending:
                if w.job == job:
                    self._pending.remove(w)
                    return True
            return False

    def _order(self) -> list[_Waiting]:
        """The waiting jobs in the order they start (round-robin between users); the caller holds the condition.

        Each step takes the user whose last start is the longest ago (never: first;
        a tie goes to the older job), and that user's oldest job.
        """
        by_user: dict[str, deque[_Waiting]] = {}
        for w in self._pending:
            by_user.setdefault(w.user, deque()).append(w)
        last = dict(self._served)
        tick = self._tick
        out: list[_Waiting] = []
        while by_user:
            user = min(by_user, key=lambda u: (last.get(u, -1), by_user[u][0].seq))
            out.append(by_user[user].popleft())
            tick += 1
            last[user] = tick
            if not by_user[user]:
                del by_user[user]
        return out

    def order(self) -> list[Job]:
        """The jobs waiting, in the order they will start (the round-robin between users)."""
        with self._cond:
            return [w.job for w in self._order()]

    def position(self, job: Job) -> dict[str, int] | None:
        """A waiting job's place: ``{"position": 1-based place among all waiting jobs, "ahead": jobs before it,
        "queued": jobs waiting}``; None when it is not waiting."""
        with self._cond:
            order = self._order()
        for i, w in enumerate(order):
            if w.job == job:
                return {"position": i + 1, "ahead": i, "queued": len(order)}
        return None

    def stop(self, run_id: str) -> None:
        """Send the design worker of ``run_id`` SIGINT (now, or as soon as it has started); kill it after the grace."""
        with self._cond:
            self._stop_asked.add(run_id)
            self._cond.notify_all()

    def running(self) -> dict[str, int | None]:
        """Run id -> worker pid of the design jobs running now (None on a cluster)."""
        with self._cond:
            return {j.run_id: r.process.pid for j, r in self._running.items() if j.kind == "design"}

    def queued(self) -> list[Job]:
        """The jobs waiting, in the order they were submitted."""
        with self._cond:
            return [w.job for w in self._pending]

    def slots(self) -> int:
        """How many jobs run at once: ``jobs``, or the cluster's threads."""
        return self.jobs if self.cluster is None else self.cluster.slots()

    def shutdown(self, timeout_s: float | None = None) -> None:
        """Stop accepting jobs; SIGINT every running worker and wait for them (killed after the grace)."""
        with self._cond:
            self._accepting = False
            self._pending.clear()  # they stay "queued" in their records and are queued again at the next start
            for job, r in self._running.items():
                self._signal(r)
            self._cond.notify_all()
        deadline = time.perf_counter() + (self.grace_s if timeout_s is None else timeout_s) + 5
        while time.perf_counter() < deadline:
            with self._cond:
                if not self._running or self._thread is None or not self._thread.is_alive():
                    break
            time.sleep(POLL_S)
        with self._cond:
            self._quit = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=5)
        for r in list(self._running.values()):  # the scheduler is gone (or stuck): end them here
            r.process.kill()
            r.process.join(timeout=5)
            self._reap(r)
        self._running.clear()

    def abandon(self) -> None:
        """Stop the scheduler at once and forget the workers, touching no record (what a crash of the server does).

        For tests of a restart: the workers are left running (their parent
        watch does not fire, since this process lives on); kill them yourself.
        """
        with self._cond:
            self._accepting = False
            self._quit = True
            self._pending.clear()
            self._running.clear()
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=5)

    # ------------------------------------------------------------------ the scheduler thread

    def _loop(self) -> None:
        while True:
            # outside the lock: on a cluster this asks the scheduler (at most every few seconds, bounded)
            slots = self.slots() if self._pending and self._accepting else 0
            with self._cond:
                if self._quit:
                    return
                for r in list(self._running.values()):
                    if r.job.kind == "design" and r.job.run_id in self._stop_asked and r.stop_sent is None:
                        self._signal(r)
                    if r.stop_sent is not None and not r.killed and time.perf_counter() - r.stop_sent > self.grace_s:
                        print(f"studio: worker of {r.job.run_id} did not stop within {self.grace_s:g} s; killed",
                              file=sys.stderr)
                        r.process.kill()
                        r.killed = True
                ended = [r for r in self._running.values() if not r.process.is_alive()]
                for r in ended:
                    del self._running[r.job]
                    self._stop_asked.discard(r.job.run_id)
                start: list[Job] = []
                for w in self._order():
                    if not self._accepting or len(self._running) + len(start) >= slots:
                        break
                    if w.job not in self._running:  # else wait until its earlier worker has ended
                        self._pending.remove(w)
                        self._tick += 1
                        self._served[w.user] = self._tick
                        start.append(w.job)
            for r in ended:
                r.process.join(timeout=1)
                self._reap(r)
            for job in start:
                self._launch(job)
            with self._cond:
                if not ended and not start:
                    self._cond.wait(POLL_S)

    def _signal(self, r: _Running) -> None:
        """SIGINT to a worker (once); the caller holds the condition."""
        if r.stop_sent is None:
            r.stop_sent = time.perf_counter()
            r.process.interrupt()

    def _launch(self, job: Job) -> None:
        """Mark the job running (if it is still queued) and start its worker."""
        ok = [False]

        def mark(rec: dict[str, Any]) -> None:
            if job.kind == "design":
                if rec.get("status") != "queued":
                    return  # cancelled or deleted while it waited
                rec.update(status="running", started=now_iso(), finished=None, error=None)
            else:
                e = job_entry(rec, job)
                if not e or e.get("status") != "queued":
                    return
                e.update(status="running", started=now_iso(), error=None)
            ok[0] = True

        try:
            self.ws.update_run(job.run_id, mark)
        except NotFound:
            return
        if not ok[0]:
            return
        if job.kind == "design":  # a resumed run starts its progress afresh
            (self.ws.runs / job.run_id / "progress.json").unlink(missing_ok=True)
        root = str(self.ws.root)
        proc = LocalWorker(self._ctx, root, job) if self.cluster is None else self.cluster.worker(root, job,
                                                                                                 self.grace_s)
        try:
            proc.start()
        except OSError as exc:  # no memory or process slots left: the run says so and can be resumed
            self._fail(job, f"could not start a worker process: {exc}; resume it later")
            return
        with self._cond:
            if self._quit:  # abandoned while it started
                return
            r = _Running(job, proc)
            self._running[job] = r
            if not self._accepting or (job.kind == "design" and job.run_id in self._stop_asked):
                self._signal(r)

    def _reap(self, r: _Running) -> None:
        """A worker has ended: when it did not record its end, record it (cancelled, interrupted or failed)."""
        job = r.job
        log = f"runs/{job.run_id}/worker.log"
        why = r.process.ended_why()

        def change(rec: dict[str, Any]) -> None:
            if job.kind == "design":
                status = rec.get("status")
                if status not in ("running", "cancelling"):
                    return  # the worker recorded its end
                if status == "cancelling":
                    rec.update(status="cancelled", error="cancelled (the worker was stopped); resume continues "
                               "after the last stage that had finished", finished=now_iso())
                elif not self._accepting:
                    rec.update(status="interrupted", error="the studio stopped while this design was running; "
                               "resume continues after the last stage that had finished", finished=now_iso())
                else:
                    rec.update(status="failed", finished=now_iso(),
                               error=f"the design worker stopped unexpectedly ({why}); what it said is in {log}. "
                               "Resume continues after the last stage that had finished")
            else:
                e = job_entry(rec, job)
                what, again = (("verify under the room light", "Ask for it again") if job.kind == "lit"
                               else ("export", "Start the export again"))
                # "running" only: a "queued" entry is a new request, made while this worker was ending (an
                # export asked for again the moment the last one was done), and starts once it has ended
                if e and e.get("status") == "running":
                    e.update(status="failed", error=f"the {what} worker stopped unexpectedly ({why}); what it "
                             f"said is in {log}. {again}", **({"progress": None} if job.kind == "lit" else {}))

        try:
            self.ws.update_run(job.run_id, change)
        except NotFound:
            pass

    def _fail(self, job: Job, message: str) -> None:
        def change(rec: dict[str, Any]) -> None:
            if job.kind == "design":
                rec.update(status="failed", error=message, finished=now_iso())
            else:
                (job_entry(rec, job) or {}).update(status="failed", error=message)

        try:
            self.ws.update_run(job.run_id, change)
        except NotFound:
            pass
