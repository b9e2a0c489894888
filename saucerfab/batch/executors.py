"""Where jobs run: this process, a local process pool, or a Dask distributed cluster.

Every engine runs the same function, :func:`saucerfab.batch.jobs.execute`, on
a :class:`~saucerfab.batch.jobs.Payload` that carries the job's input bytes,
and hands back a :class:`~saucerfab.batch.jobs.JobResult` that carries the
output bytes; the driver writes the output folders. So a Dask worker needs
saucerfab installed (the same version as the driver: checked on connect) but
no shared file system, and a worker that dies writes nothing.

An engine has ``slots`` (how many jobs to keep in flight), ``submit``,
``wait`` (finished jobs, as results or :data:`WORKER_DIED`), ``events``
(stage starts reported by workers) and ``close``.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import logging
import multiprocessing as mp
import os
import queue
import signal
import threading
import time
import uuid
from typing import Any

from saucerfab import __version__
from saucerfab.batch.jobs import JobResult, Payload, execute, set_event_sink
from saucerfab.errors import ConfigError

#: a job whose worker process died (killed, out of memory) before it answered
WORKER_DIED = "worker-died"


class InProcessEngine:
    """Runs each job in this process, one at a time (``--workers 0``: debugging, tests)."""

    name = "in-process"
    slots = 1
    #: jobs run in the driver's thread: Ctrl-C must interrupt them there (see runner)
    runs_jobs_here = True
    scratch_in_output = True

    def __init__(self) -> None:
        self._done: list[tuple[Any, Any]] = []
        self._events: list[tuple[str, str]] = []

    def submit(self, payload: Payload) -> Any:
        handle = object()
        set_event_sink(lambda job, stage: self._events.append((job, stage)))
        try:
            self._done.append((handle, execute(payload)))
        finally:
            set_event_sink(None)
        return handle

    def wait(self, handles: list[Any], timeout: float) -> list[tuple[Any, Any]]:
        done, self._done = self._done, []
        return done

    def events(self) -> list[tuple[str, str]]:
        ev, self._events = self._events, []
        return ev

    def close(self, cancel: bool = False) -> None:
        pass


# --------------------------------------------------------------------------- local pool


def _watch_parent(parent: int) -> None:
    # A pool worker whose driver was killed (kill -9) would otherwise wait for
    # work forever: leave as soon as the parent is gone.
    while True:
        time.sleep(0.5)
        if os.getppid() != parent:
            os._exit(0)


def _init_pool_worker(events: Any, parent: int, threads: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(threads))
    set_event_sink(lambda job, stage: events.put((job, stage)))
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()


#: seconds a pool worker has to exit after SIGTERM before it is sent SIGKILL (Ctrl-C, a broken pool)
STOP_GRACE_S = 5.0
#: seconds a stopped pool's manager thread is waited for (it has nothing left to wait on by then)
STOP_JOIN_S = 10.0


def _alive(proc: Any) -> bool:
    try:
        return bool(proc.is_alive())
    except Exception:  # noqa: BLE001 - a process object already closed is not alive
        return False


class LocalPoolEngine:
    """A pool of ``workers`` processes on this machine (spawned, so nothing of the
    driver's state or threads leaks into them). A worker that dies (killed, out
    of memory) breaks the pool: its in-flight jobs come back as
    :data:`WORKER_DIED` and a fresh pool takes the rest."""

    scratch_in_output = True

    def __init__(self, workers: int, threads: int = 1) -> None:
        if workers < 1:
            raise ConfigError(f"--workers must be at least 1 for a process pool, got {workers}")
        self.workers = workers
        self.threads = threads
        self.name = f"local process pool, {workers} worker{'s' if workers != 1 else ''}"
        self._ctx = mp.get_context("spawn")
        self._events = self._ctx.Queue()
        self._pool: cf.ProcessPoolExecutor | None = None

    @property
    def slots(self) -> int:
        return self.workers

    def _get_pool(self) -> cf.ProcessPoolExecutor:
        if self._pool is None:
            self._pool = cf.ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=self._ctx,
                initializer=_init_pool_worker,
                initargs=(self._events, os.getpid(), self.threads),
            )
        return self._pool

    def submit(self, payload: Payload) -> Any:
        try:
            return self._get_pool().submit(execute, payload)
        except cf.BrokenExecutor:
            self._discard_pool()
            return self._get_pool().submit(execute, payload)

    def wait(self, handles: list[Any], timeout: float) -> list[tuple[Any, Any]]:
        done, _ = cf.wait(handles, timeout=timeout, return_when=cf.FIRST_COMPLETED)
        out: list[tuple[Any, Any]] = []
        broken = False
        for fut in done:
            try:
                out.append((fut, fut.result()))
            except cf.BrokenExecutor:
                broken = True
                out.append((fut, WORKER_DIED))
        if broken:
            self._discard_pool()
        return out

    def events(self) -> list[tuple[str, str]]:
        ev = []
        while True:
            try:
                ev.append(self._events.get_nowait())
            except (queue.Empty, OSError, ValueError):
                return ev

    def _discard_pool(self) -> None:
        if self._pool is not None:
            self._terminate(self._pool)
            self._pool = None

    @staticmethod
    def _terminate(pool: cf.ProcessPoolExecutor) -> None:
        """Stop ``pool`` now, in bounded time: its workers killed, its jobs dropped.

        Each worker gets SIGTERM, then SIGKILL after :data:`STOP_GRACE_S`, and is
        reaped. Only then the driver's own copy of the result pipe's write end
        is closed: a worker killed while it was sending a result leaves half a
        message in the pipe, and the executor's manager thread, reading it,
        would wait for the rest forever; with no writer left it reads EOF and
        winds the pool up as broken. The manager thread is joined for at most
        :data:`STOP_JOIN_S` (``shutdown(wait=True)`` could wait forever).
        """
        manager = getattr(pool, "_executor_manager_thread", None)
        procs = list((getattr(pool, "_processes", None) or {}).values())
        for proc in procs:
            with contextlib.suppress(Exception):
                proc.terminate()
        deadline = time.monotonic() + STOP_GRACE_S
        for proc in procs:
            with contextlib.suppress(Exception):
                proc.join(max(0.0, deadline - time.monotonic()))
        for proc in procs:
            with contextlib.suppress(Exception):
                if proc.is_alive():
                    proc.kill()
                    proc.join(STOP_GRACE_S)
        if all(not _alive(proc) for proc in procs):
            writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
            with contextlib.suppress(Exception):
                if writer is not None:
                    writer.close()
        pool.shutdown(wait=False, cancel_futures=True)
        if manager is not None and manager is not threading.current_thread():
            manager.join(STOP_JOIN_S)

    def close(self, cancel: bool = False) -> None:
        if self._pool is None:
            return
        if cancel:
            self._terminate(self._pool)
        else:
            self._pool.shutdown(wait=True)
        self._pool = None
        self._events.close()
        self._events.join_thread()


# --------------------------------------------------------------------------- Dask


def _worker_version() -> str:
    import saucerfab

    return saucerfab.__version__


#: loggers of Dask (and of tornado, its event loop) that the driver silences
#: while a batch runs on a cluster; see :class:`QuietDaskLogs`
DASK_LOGGERS = ("distributed", "tornado")
#: cancellation reasons of a Dask future that mean the driver lost the
#: scheduler, not that a worker died (distributed's own words)
SCHEDULER_GONE = ("scheduler-connection-lost", "scheduler-restart")


#: pauses before each further try to send a job to the cluster (about 30 s in all: a
#: killed worker is noticed by the scheduler within a second on a local
#: network; a scatter to it fails until then)
SUBMIT_PAUSES_S = (0.1, 0.3, 1.0, 3.0, 10.0, 15.0)


#: seconds the driver waits for the cluster's size, and for the client to close
SLOTS_TIMEOUT_S = 5.0
CLOSE_TIMEOUT_S = 10.0
#: a scatter may take this long, plus the payload's bytes at the rate below
SCATTER_TIMEOUT_S = 10.0
SCATTER_MIN_BYTES_PER_S = 20e6


class _Unsent:
    """The handle of a job the cluster did not take (see :meth:`DaskEngine.submit`)."""

    def __init__(self, job_id: str) -> None:
        self.job_id = job_id


class QuietDaskLogs:
    """Keep Dask's own log records (and their tracebacks) off the user's terminal.

    Dask's client logs to stderr when the scheduler goes away or a worker
    dies ("Removing worker ... caused the cluster to lose scattered data",
    reconnect attempts, tracebacks of its callbacks). The batch reports each
    of those in its own words (the job is run again, or failed with the
    reason), so during a batch the records are dropped: every existing
    ``distributed.*`` and ``tornado.*`` logger is raised above CRITICAL (a
    logger made later inherits that from its parent), and :meth:`restore`
    puts each level back.
    """

    def __init__(self) -> None:
        self._saved: list[tuple[logging.Logger, int]] = []

    def silence(self) -> None:
        """Raise every Dask logger above CRITICAL (after ``distributed`` is imported:
        its import configures them)."""
        names = {n for n in logging.root.manager.loggerDict if n.split(".")[0] in DASK_LOGGERS}
        for name in sorted(names | set(DASK_LOGGERS)):
            lg = logging.getLogger(name)
            self._saved.append((lg, lg.level))
            lg.setLevel(logging.CRITICAL + 1)

    def restore(self) -> None:
        """Put back the levels :meth:`silence` changed."""
        for lg, level in reversed(self._saved):
            lg.setLevel(level)
        self._saved.clear()


class DaskEngine:
    """Jobs as tasks on an existing Dask distributed cluster (``tcp://HOST:PORT``).

    The payload (with the input bytes) is scattered to the cluster and the
    result (with the output bytes) comes back to this driver, which writes it:
    workers need saucerfab of the same version, not the driver's files.
    Stage events travel as worker events (``log_event`` / ``subscribe_topic``).

    A worker process that dies (killed, out of memory) costs no job: its
    jobs come back as :data:`WORKER_DIED` and the driver starts each once
    more (``runner.MAX_ATTEMPTS``, as for the local pool), with its payload
    scattered again. Two ways lead there: the scheduler gives up on a task
    that killed workers (``KilledWorker``, after its ``allowed-failures``), or,
    far more often, the dead worker held the job's scattered payload, which
    nothing can recompute, so the scheduler cancels the task. A cancellation
    because this driver lost the scheduler (it died or restarted) is not a
    worker's death: those jobs fail with that reason (rerun to resume).

    Dask's own log lines are kept off the terminal while the engine is open
    (:class:`QuietDaskLogs`). In a worker process with several threads,
    designs run one at a time (see ``jobs._DESIGN_LOCK``); one thread per
    worker process (``--nthreads 1``) uses a machine best.
    """

    scratch_in_output = False

    def __init__(self, address: str, *, connect_timeout: float = 30.0, threads: int = 1) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ConfigError(
                "--scheduler needs Dask distributed: pip install 'saucerfab[cluster]'"
            ) from None
        if "://" not in address:
            raise ConfigError(f"--scheduler {address!r}: give the scheduler address as tcp://HOST:PORT")
        self.address = address
        self.threads = threads
        self.name = f"Dask cluster {address}"
        self._quiet = QuietDaskLogs()
        self._quiet.silence()
        try:
            self._connect(Client, address, connect_timeout)
        except BaseException:
            self._quiet.restore()
            raise

    def _connect(self, client_cls: Any, address: str, connect_timeout: float) -> None:
        """Connect, wait for a worker, check the workers' saucerfab version, subscribe to events."""
        try:
            self.client = client_cls(address, timeout=connect_timeout, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise ConfigError(
                f"cannot reach the Dask scheduler at {address!r} ({exc}); is it running and reachable?"
            ) from None
        try:
            self.client.wait_for_workers(1, timeout=connect_timeout)
        except (TimeoutError, OSError):
            self.client.close()
            raise ConfigError(f"the Dask cluster at {address!r} has no workers") from None
        versions = self.client.run(_worker_version)
        wrong = {w: v for w, v in versions.items() if v != __version__}
        if wrong:
            self.client.close()
            raise ConfigError(
                f"Dask workers run another saucerfab version than this driver ({__version__}): {wrong}; "
                "install the same version on every worker"
            )
        self.topic = f"saucerfab-batch-{uuid.uuid4().hex}"
        self._events: queue.SimpleQueue[tuple[str, str]] = queue.SimpleQueue()
        self.client.subscribe_topic(self.topic, self._on_event)
        self._slots_at = 0.0
        self._slots = 2
        self._scattered: dict[Any, Any] = {}
        self._finished: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._unsent: list[tuple[_Unsent, str]] = []

    def _on_event(self, event: Any) -> None:
        try:
            _, msg = event
            self._events.put((str(msg["job"]), str(msg["stage"])))
        except (TypeError, ValueError, KeyError):
            pass

    @property
    def slots(self) -> int:
        now = time.monotonic()
        if now - self._slots_at > 5.0 and self.client.status == "running":
            try:
                # bounded: a scheduler that has just died would hold the call for
                # the client's whole reconnect timeout (30 s)
                self._slots = max(2, 2 * sum(self.client.nthreads(callback_timeout=SLOTS_TIMEOUT_S).values()))
            except Exception:  # noqa: BLE001 - keep the last known size
                pass
            self._slots_at = now
        return self._slots

    def submit(self, payload: Payload) -> Any:
        """Scatter the payload and submit its task; a job that cannot be sent comes
        back from :meth:`wait` as a failure (the batch goes on with the others)."""
        from saucerfab.batch.jobs import execute as run

        payload.event_topic = self.topic
        payload.scratch_root = None
        error: Exception | None = None
        # a scatter to a scheduler that has just died waits for the client to
        # reconnect (up to its connect timeout); bound it by what the bytes need
        size = sum(len(b) for b in payload.files.values())
        timeout = SCATTER_TIMEOUT_S + size / SCATTER_MIN_BYTES_PER_S
        for pause in (0.0, *SUBMIT_PAUSES_S):
            if pause:
                time.sleep(pause)
            if self.client.status != "running":
                break  # the scheduler is gone (the client is reconnecting or closed): fail the job now
            try:
                data = self.client.scatter(payload, hash=False, timeout=timeout)
                fut = self.client.submit(
                    run, data, key=f"saucerfab-job-{payload.job_id}-{uuid.uuid4().hex[:8]}", pure=False
                )
            except Exception as exc:  # noqa: BLE001 - CommClosedError, TimeoutError...: see below
                # The scatter went to a worker that has just died, and the
                # scheduler has not noticed yet: try again once it has.
                error = exc
                continue
            self._scattered[fut.key] = data
            fut.add_done_callback(self._finished.put)
            return fut
        handle = _Unsent(payload.job_id)
        if self.client.status != "running":
            why = self._lost_scheduler(str(self.client.status))
        else:
            why = (
                f"the Dask cluster at {self.address!r} did not take the job ({type(error).__name__}: {error}); "
                "rerun the batch once the cluster is up again (finished jobs are kept)"
            )
        self._unsent.append((handle, why))
        return handle

    def _lost_scheduler(self, detail: str) -> str:
        """A job's failure reason when this driver has lost the scheduler."""
        return (
            f"the batch lost the Dask scheduler at {self.address!r} ({detail}); "
            "rerun the batch once the scheduler is up again (finished jobs are kept)"
        )

    def wait(self, handles: list[Any], timeout: float) -> list[tuple[Any, Any]]:
        out: list[tuple[Any, Any]] = []
        if self._unsent:
            out, self._unsent = self._unsent, []
            timeout = 0.0  # answer those now
        done = []
        try:
            done.append(self._finished.get(timeout=timeout))
            while True:
                done.append(self._finished.get_nowait())
        except queue.Empty:
            pass
        for fut in done:
            self._scattered.pop(fut.key, None)
            out.append((fut, self._outcome(fut)))
            try:
                fut.release()
            except Exception:  # noqa: BLE001 - the scheduler may be gone; nothing to release then
                pass
        return out

    def _outcome(self, fut: Any) -> Any:
        """The :class:`JobResult` of a done task, :data:`WORKER_DIED`, or a failure reason."""
        if fut.status == "cancelled":
            return self._cancelled(fut)
        try:
            if fut.status == "finished":
                return fut.result()  # fetched from the worker that holds it
            exc = fut.exception()
        except Exception as err:  # noqa: BLE001 - CommClosedError, OSError...: the result is out of reach
            if self.client.status != "running":
                return self._lost_scheduler(f"{type(err).__name__} while fetching the job's result")
            # the scheduler is up, the worker holding the result is not: run the job again
            return WORKER_DIED
        name = type(exc).__name__
        if name == "KilledWorker":
            return WORKER_DIED
        return f"the task failed on the cluster: {name}: {exc}"

    def _cancelled(self, fut: Any) -> str:
        """What a cancelled task means: :data:`WORKER_DIED` (run it again), or a failure
        reason when this driver lost the scheduler."""
        try:
            fut.result(timeout=1)  # raises the cancellation, which carries distributed's reason
            reason = ""
        except Exception as exc:  # noqa: BLE001 - FutureCancelledError, or anything odd
            reason = str(getattr(exc, "reason", "") or "")
        if reason in SCHEDULER_GONE or self.client.status != "running":
            return self._lost_scheduler(reason or str(self.client.status))
        # The scheduler is there and cancelled the task itself: the worker that
        # held the job's scattered payload died ("lost dependencies", or no
        # reason given). The payload is still here, so the job can run again.
        return WORKER_DIED

    def events(self) -> list[tuple[str, str]]:
        ev = []
        while True:
            try:
                ev.append(self._events.get_nowait())
            except queue.Empty:
                return ev

    def close(self, cancel: bool = False) -> None:
        # Closing the client releases its futures: the scheduler drops the
        # tasks nobody wants any more (``cancel`` needs nothing else).
        try:
            try:
                self.client.unsubscribe_topic(self.topic)
            except Exception:  # noqa: BLE001 - closing must not hide the batch's own outcome
                pass
            self._scattered.clear()
            self.client.close(timeout=CLOSE_TIMEOUT_S)
        finally:
            self._quiet.restore()  # after the client's close: it logs too when the scheduler is gone


def make_engine(workers: int, scheduler: str | None, threads: int = 1) -> Any:
    """The engine for ``--workers`` / ``--scheduler``."""
    if scheduler:
        return DaskEngine(scheduler, threads=threads)
    if workers == 0:
        return InProcessEngine()
    return LocalPoolEngine(workers, threads=threads)


__all__ = [
    "WORKER_DIED",
    "DaskEngine",
    "InProcessEngine",
    "JobResult",
    "LocalPoolEngine",
    "QuietDaskLogs",
    "make_engine",
]
