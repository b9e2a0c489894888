"""The studio's jobs on a Dask distributed cluster (``saucerfab studio --scheduler tcp://HOST:PORT``).

The simplest honest design: a Dask task runs the same worker as on this
machine (:func:`saucerfab.studio.worker.main`, in a child process of the
Dask worker: ``python -m saucerfab.studio.worker``) with the run folder's
path, so the worker writes its progress, looks, design and record into the
run folder itself. That needs the workspace on a filesystem every Dask
worker sees at the same path (NFS, a cluster filesystem, or workers on this
machine): :meth:`DaskCluster.probe` checks it at start with a task that
reads a file the studio wrote in the workspace and writes its answer there,
and the studio refuses to start otherwise. The studio keeps the queue, the
round-robin between users and the records (a run's record is changed under
its ``flock``, which NFS v4 and cluster filesystems honour).

Stopping a job: the studio writes ``runs/<id>/.stop``; the task sends its
child SIGINT (``run_design`` saves the checkpoint, as on this machine) and
kills it after the grace; a task that has not started yet finds the stop
file and returns at once. A job still there after the studio's own grace is
cancelled with Dask's ``Future.cancel``.
Connecting, the version check and the quiet Dask logs are
``saucerfab batch --scheduler``'s (:mod:`saucerfab.batch.executors`).
"""

from __future__ import annotations

import os
import secrets
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

from saucerfab import __version__
from saucerfab.errors import ConfigError
from saucerfab.files.fileio import write_text_atomic

#: the file in a run folder that asks the job running it on the cluster to stop
STOP_FILE = ".stop"
#: how often a cluster task looks at its child and the stop file, seconds
TASK_POLL_S = 0.2
#: seconds the studio waits for the cluster's workers, its size, the probe
CONNECT_TIMEOUT_S = 30.0
SLOTS_EVERY_S = 5.0
SLOTS_TIMEOUT_S = 5.0
PROBE_TIMEOUT_S = 60.0
CLOSE_TIMEOUT_S = 10.0


# --------------------------------------------------------------------------- on the Dask worker


def run_job(root: str, kind: str, run_id: str, printer: str | None, grace_s: float) -> int:
    """A Dask task: the studio's worker for one job, as a child process; returns its exit code.

    The child is ``python -m saucerfab.studio.worker`` (a Dask worker's
    process may not start ``multiprocessing`` children, and a thread cannot
    be stopped with SIGINT). The run folder's ``.stop`` stops it.
    """
    stop = Path(root) / "runs" / run_id / STOP_FILE
    if stop.exists():  # cancelled while it waited on the cluster: the studio records it
        return 0
    args = [sys.executable, "-m", "saucerfab.studio.worker", root, kind, run_id] + ([printer] if printer else [])
    child = subprocess.Popen(args, stdin=subprocess.DEVNULL)
    sent: float | None = None
    try:
        while child.poll() is None:
            if sent is None and stop.exists():
                sent = time.monotonic()
                child.send_signal(signal.SIGINT)
            elif sent is not None and time.monotonic() - sent > grace_s:
                child.kill()
            time.sleep(TASK_POLL_S)
    finally:
        if child.poll() is None:  # the task itself was stopped (its worker closing): the child goes too
            child.send_signal(signal.SIGINT)
            try:
                child.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                child.kill()
    return int(child.returncode)


def _probe(root: str, name: str) -> str:
    """A Dask task: read the probe file the studio wrote in the workspace and write the answer beside it."""
    path = Path(root) / name
    nonce = path.read_text(encoding="utf-8")
    write_text_atomic(path.with_suffix(".answer"), nonce[::-1])
    return socket.gethostname()


def _worker_version() -> str:
    import saucerfab

    return saucerfab.__version__


# --------------------------------------------------------------------------- in the studio


class DaskWorker:
    """One job as a task on the cluster, with :class:`saucerfab.studio.jobs.LocalWorker`'s interface."""

    pid = None  # no process of this machine

    def __init__(self, client: Any, root: str, job: Any, grace_s: float) -> None:
        self.client = client
        self.root = root
        self.job = job
        self.grace_s = grace_s
        self.stop = Path(root) / "runs" / job.run_id / STOP_FILE
        self.future: Any = None

    def start(self) -> None:
        self.stop.unlink(missing_ok=True)  # a stop asked of an earlier attempt
        try:
            self.future = self.client.submit(
                run_job, self.root, self.job.kind, self.job.run_id, self.job.printer, self.grace_s,
                key=f"saucerfab-studio-{self.job.kind}-{self.job.run_id}-{uuid.uuid4().hex[:8]}", pure=False)
        except Exception as exc:  # noqa: BLE001 - the scheduler is gone: the run says so (jobs._fail)
            raise OSError(f"the Dask cluster did not take the job ({type(exc).__name__}: {exc})") from None

    def is_alive(self) -> bool:
        return self.future is not None and not self.future.done()

    def interrupt(self) -> None:
        """Ask the task to stop its child (SIGINT: the checkpoint is saved); a task not started yet returns at once.

        Not Dask's cancel: a client's future says ``pending`` while its task
        runs, and a cancelled future would end here while the child still
        saves its checkpoint and records the end (:meth:`kill` cancels, after the grace).
        """
        try:
            write_text_atomic(self.stop, "stop\n")
        except OSError:  # the run folder is gone (deleted): nothing to stop
            pass

    def kill(self) -> None:
        """Dask's cancel (the task's own grace kills its child)."""
        if self.future is not None:
            self.future.cancel()

    def join(self, timeout: float | None = None) -> None:
        pass  # done() is the end; the result is read in ended_why

    def ended_why(self) -> str:
        """How the task ended, in words for a run's error."""
        fut = self.future
        if fut is None:
            return "not sent to the cluster"
        try:
            if fut.status == "finished":
                code = int(fut.result(timeout=5))
                return f"killed by signal {-code}" if code < 0 else f"exit code {code}"
            if fut.status == "cancelled":
                return "the Dask task was cancelled"
            exc = fut.exception(timeout=5)
            return f"the Dask task failed: {type(exc).__name__}: {exc}"
        except Exception as exc:  # noqa: BLE001 - the scheduler or the worker is gone
            return f"the cluster lost the task ({type(exc).__name__})"
        finally:
            try:
                fut.release()
            except Exception:  # noqa: BLE001 - nothing to release once the scheduler is gone
                pass


class DaskCluster:
    """The studio's connection to a Dask scheduler: where :class:`~saucerfab.studio.jobs.JobQueue` sends its jobs.

    Args:
        address: ``tcp://HOST:PORT`` of the scheduler.
        root: the workspace folder (checked with :meth:`probe`).

    Raises:
        ConfigError: no Dask distributed, a bad address, no scheduler or no
            workers there, workers of another saucerfab version, or workers
            that do not see the workspace.
    """

    def __init__(self, address: str, root: str | os.PathLike[str], *,
                 connect_timeout: float = CONNECT_TIMEOUT_S) -> None:
        from saucerfab.batch.executors import QuietDaskLogs

        try:
            from distributed import Client
        except ImportError:
            raise ConfigError("--scheduler needs Dask distributed: pip install 'saucerfab[cluster]'") from None
        if "://" not in address:
            raise ConfigError(f"--scheduler {address!r}: give the scheduler address as tcp://HOST:PORT")
        self.address = address
        self.root = str(Path(root).resolve())
        self._quiet = QuietDaskLogs()
        self._quiet.silence()
        try:
            try:
                self.client = Client(address, timeout=connect_timeout, set_as_default=False)
            except (OSError, TimeoutError) as exc:
                raise ConfigError(f"cannot reach the Dask scheduler at {address!r} ({exc}); is it running and "
                                  "reachable?") from None
            try:
                self._check(connect_timeout)
            except BaseException:
                self.client.close()
                raise
        except BaseException:
            self._quiet.restore()
            raise
        self._slots = 1
        self._slots_at = 0.0

    def _check(self, connect_timeout: float) -> None:
        try:
            self.client.wait_for_workers(1, timeout=connect_timeout)
        except (TimeoutError, OSError):
            raise ConfigError(f"the Dask cluster at {self.address!r} has no workers") from None
        versions = self.client.run(_worker_version)
        wrong = {w: v for w, v in versions.items() if v != __version__}
        if wrong:
            raise ConfigError(f"Dask workers run another saucerfab version than this studio ({__version__}): "
                              f"{wrong}; install the same version on every worker")
        self.probe()

    def probe(self) -> None:
        """Check that the workers see the workspace: one task per worker reads a file written here and writes
        its answer, which must come back here.

        Raises:
            ConfigError: a worker does not see it (its own filesystem), or cannot write in it.
        """
        name = f".probe-{secrets.token_hex(8)}"
        path = Path(self.root) / name
        nonce = secrets.token_hex(16)
        write_text_atomic(path, nonce)
        answer = path.with_suffix(".answer")
        try:
            for worker in self.client.scheduler_info()["workers"]:
                answer.unlink(missing_ok=True)
                try:
                    host = self.client.submit(_probe, self.root, name, workers=[worker], allow_other_workers=False,
                                              pure=False).result(timeout=PROBE_TIMEOUT_S)
                    seen = answer.read_text(encoding="utf-8") == nonce[::-1]
                except (OSError, TimeoutError) as exc:
                    host, seen = f"{worker} ({type(exc).__name__}: {exc})", False
                if not seen:
                    raise ConfigError(
                        f"the Dask worker {host} does not see the studio's workspace {self.root!r}: the workers "
                        "write the designs into its run folders, so the workspace must be on a filesystem every "
                        "worker mounts at the same path (NFS, a cluster filesystem), with write access; give such "
                        "a --workspace, or run the workers on this machine"
                    )
        finally:
            path.unlink(missing_ok=True)
            answer.unlink(missing_ok=True)

    def slots(self) -> int:
        """Jobs at once: the cluster's threads (looked up every :data:`SLOTS_EVERY_S` seconds)."""
        now = time.monotonic()
        if now - self._slots_at > SLOTS_EVERY_S and self.client.status == "running":
            try:  # bounded: a scheduler that has just died would hold the call for the reconnect timeout
                self._slots = max(1, sum(self.client.nthreads(callback_timeout=SLOTS_TIMEOUT_S).values()))
            except Exception:  # noqa: BLE001 - keep the last known size
                pass
            self._slots_at = now
        return self._slots

    def worker(self, root: str, job: Any, grace_s: float) -> DaskWorker:
        """The handle of ``job`` on the cluster (started by the queue)."""
        return DaskWorker(self.client, root, job, grace_s)

    def close(self) -> None:
        try:
            self.client.close(timeout=CLOSE_TIMEOUT_S)
        finally:
            self._quiet.restore()
