"""The lib3mf stage of the 3MF check: the 3MF Consortium's own reader as a second opinion.

Every 3MF that the bounded reader (:mod:`saucerfab.check.readers.threemf`)
has read, so one that passed its budgets (zip, XML, counts, pixels), goes
to lib3mf as well, the reader the Consortium maintains and printer
software builds on. lib3mf is native code reading a stranger's file, so it
runs in child processes (:mod:`saucerfab.check.readers.lib3mf_worker`):

* where the platform can fork, one *fork server* per checking process
  (started on the first 3MF, restarted if it dies, stopped at exit; a
  forked batch worker starts its own) loads lib3mf once and reads each file
  in a freshly forked child: ~3-10 ms per small file instead of ~30-55 ms
  for a fresh interpreter (measured on the 2-core development machine;
  importing lib3mf's generated Python bindings would add another ~70 ms).
  Elsewhere, one fresh child per file;
* the child that reads a file limits its own address space (``RLIMIT_AS``,
  where the platform has it; :func:`memory_limit`), CPU time and core
  dumps, and is killed after a wall-clock timeout (:func:`timeout_s`): a
  crash, a hang or a memory blow-up gives a ``lib3mf_not_run`` warning,
  never a failed ``check`` or batch worker; a server that stops answering
  is killed too (:data:`SERVER_GRACE_S` past the file's timeout);
* one read in lib3mf's default mode gives both verdicts: a fatal error,
  and the warnings strict mode would refuse at (see the worker).

Findings (:func:`lib3mf_findings`):

* ``lib3mf_rejects`` (error): lib3mf refuses the file, with its message;
  an *info* when the checker's own ``spec_violation`` findings already
  make the file not printable (they say what to fix; lib3mf's message is
  kept as corroboration). lib3mf's message is reported as it is, but an
  uninformative one ("unknown error") is said to be so.
* ``lib3mf_warning`` (warning): lib3mf reads the file with warnings (its
  strict mode refuses it at the first); errors of the checker's own rules
  decide printability.
* ``lib3mf_reads`` (info): lib3mf reads it cleanly in strict mode.
* ``lib3mf_not_run``: info when lib3mf is not installed or the stage is
  off (``SAUCERFAB_LIB3MF=off``); a warning when it crashed, timed out or
  ran out of memory on this file.
"""

from __future__ import annotations

import ast
import atexit
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from saucerfab.check.report import Finding, finding

#: wall-clock seconds a file may take: a base plus a share per megabyte of the (compressed) file; lib3mf
#: reads a 1-million-triangle, 11 MB 3MF (70 MB of XML) in ~1.5 s on the 2-core development machine
TIMEOUT_BASE_S = 8.0  # a small file lib3mf chokes on costs at most this, near the checker's 10 s a file
TIMEOUT_PER_MB_S = 0.5
TIMEOUT_MAX_S = 300.0
#: address space the reading process may use: a base plus a multiple of the file. That 1-million-triangle
#: file needs 48 MiB of address space in all (interpreter and library included; 40 MB resident)
MEMORY_BASE_BYTES = 512 << 20
MEMORY_PER_FILE_BYTE = 16
MEMORY_MAX_BYTES = 4 << 30
#: bytes of the child's output read back
MAX_OUTPUT_BYTES = 1 << 16

WORKER = Path(__file__).with_name("lib3mf_worker.py")


@dataclass
class Lib3mfResult:
    """lib3mf's verdict on one file.

    ``status``: ``read`` (no fatal error; ``warnings`` may be non-empty),
    ``rejected``, ``memory``, ``timeout``, ``crashed``, ``failed`` (the stage
    itself failed) or ``unavailable`` (lib3mf not installed, or off).
    """

    status: str
    version: str = ""
    message: str = ""
    warnings: list[tuple[int, str]] = field(default_factory=list)
    warning_count: int = 0
    elapsed_s: float = 0.0


_LIBRARY: list[str | None] = []


def library_path() -> str | None:
    """Path of lib3mf's shared library from the installed ``lib3mf`` package, without importing it."""
    if _LIBRARY:
        return _LIBRARY[0]
    path = None
    try:
        import importlib.util

        spec = importlib.util.find_spec("lib3mf")
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin:
        folder = Path(spec.origin).parent
        for name in ("lib3mf.so", "lib3mf.dylib", "lib3mf.dll"):
            if (folder / name).is_file():
                path = os.fspath(folder / name)
                break
    _LIBRARY.append(path)
    return path


def enabled() -> bool:
    return os.environ.get("SAUCERFAB_LIB3MF", "").strip().lower() not in ("0", "off", "no", "false")


def timeout_s(file_bytes: int) -> float:
    return min(TIMEOUT_MAX_S, TIMEOUT_BASE_S + TIMEOUT_PER_MB_S * file_bytes / 1e6)


def memory_limit(file_bytes: int) -> int:
    return min(MEMORY_MAX_BYTES, MEMORY_BASE_BYTES + MEMORY_PER_FILE_BYTE * file_bytes)


def worker_command(library: str, path: str, memory: int, cpu_s: int) -> list[str]:
    """The one-shot child's command line (where there is no fork server; tests replace it)."""
    return [sys.executable, "-I", "-S", os.fspath(WORKER), library, path, str(memory), str(cpu_s)]


def server_command(library: str) -> list[str]:
    """The fork server's command line (tests replace it to simulate a server that dies or hangs)."""
    return [sys.executable, "-I", "-S", os.fspath(WORKER), "--serve", library]


#: seconds the parent waits for the fork server past a file's own timeout before giving up on the server
SERVER_GRACE_S = 10.0


class _Server:
    """One fork server per process (and per forked process): started on first use, restarted after a failure."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen[bytes] | None = None
        self.pid = 0  # the process that started it
        self.library = ""
        self.lock = threading.Lock()

    def _start(self, library: str) -> subprocess.Popen[bytes]:
        if self.proc is not None and self.pid == os.getpid() and self.library == library and self.proc.poll() is None:
            return self.proc
        if self.proc is not None and self.pid == os.getpid():
            self.stop()
        self.proc = subprocess.Popen(server_command(library), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, close_fds=True)
        self.pid, self.library = os.getpid(), library
        return self.proc

    def stop(self) -> None:
        proc, self.proc = self.proc, None
        if proc is None or self.pid != os.getpid():
            return  # never touch a server another process (our parent, before a fork) started
        try:
            if proc.stdin is not None:
                proc.stdin.close()
            proc.wait(timeout=2)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        for fh in (proc.stdout,):
            if fh is not None:
                fh.close()

    def ask(self, library: str, path: str, memory: int, cpu_s: int, timeout: float) -> tuple[str, bytes]:
        """("ok", reply line), or (why it failed, b"") after stopping the server."""
        import select

        with self.lock:
            try:
                proc = self._start(library)
                assert proc.stdin is not None and proc.stdout is not None
                req = f"{os.fsencode(path).hex()} {memory} {cpu_s} {timeout:.3f}\n".encode()
                proc.stdin.write(req)
                proc.stdin.flush()
                fd = proc.stdout.fileno()
                deadline = time.monotonic() + timeout + SERVER_GRACE_S
                buf = b""
                while not buf.endswith(b"\n"):
                    left = deadline - time.monotonic()
                    if left <= 0 or not select.select([fd], [], [], left)[0]:
                        self._kill()
                        return "timeout", b""
                    chunk = os.read(fd, MAX_OUTPUT_BYTES)
                    if not chunk or len(buf) > MAX_OUTPUT_BYTES:
                        self._kill()
                        return "crashed", b""
                    buf += chunk
                return "ok", buf
            except (OSError, ValueError):
                self._kill()
                return "crashed", b""

    def _kill(self) -> None:
        proc, self.proc = self.proc, None
        if proc is not None and self.pid == os.getpid():
            proc.kill()
            proc.wait()
            for fh in (proc.stdin, proc.stdout):
                if fh is not None:
                    try:
                        fh.close()
                    except OSError:
                        pass


    def forget(self) -> None:
        """In a forked child: drop (without stopping) the parent's server, and a lock the fork may have caught held."""
        proc, self.proc = self.proc, None
        self.lock = threading.Lock()
        for fh in (proc.stdin, proc.stdout) if proc is not None else ():
            if fh is not None:
                try:
                    fh.close()  # our copies only: the parent's server sees end of input when the parent closes its own
                except OSError:
                    pass


_SERVER = _Server()
atexit.register(_SERVER.stop)
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_SERVER.forget)


def _parse(raw: bytes, elapsed: float) -> Lib3mfResult:
    try:
        out = ast.literal_eval(raw[:MAX_OUTPUT_BYTES].decode("utf-8", "replace").strip().splitlines()[-1])
        if not isinstance(out, dict):
            raise ValueError("not a dict")
    except (ValueError, SyntaxError, IndexError, MemoryError, RecursionError):
        return Lib3mfResult("crashed", message="lib3mf's process gave no readable verdict", elapsed_s=elapsed)
    warnings = [(int(w[0]), str(w[1])) for w in out.get("warnings") or [] if isinstance(w, (list, tuple)) and len(w) == 2]
    return Lib3mfResult(
        status=str(out.get("status", "failed")), version=str(out.get("version") or ""),
        message=str(out.get("message") or ""), warnings=warnings,
        warning_count=int(out.get("warning_count") or len(warnings)), elapsed_s=elapsed,
    )


def run_lib3mf(path: str | os.PathLike[str], *, fork_server: bool | None = None) -> Lib3mfResult:
    """lib3mf's verdict on the 3MF at ``path``, read in a bounded child process; never raises.

    ``fork_server``: use the fork server (default: where ``os.fork`` exists),
    else one fresh child per file.
    """
    spath = os.path.abspath(os.fspath(path))  # the server's working directory is where it started, not ours
    if not enabled():
        return Lib3mfResult("unavailable", message="the lib3mf stage is off (SAUCERFAB_LIB3MF)")
    library = library_path()
    if library is None:
        return Lib3mfResult("unavailable", message="lib3mf is not installed (pip install lib3mf)")
    try:
        size = os.stat(spath).st_size
    except OSError as exc:
        return Lib3mfResult("failed", message=f"cannot stat the file: {exc.strerror or exc}")
    limit = timeout_s(size)
    memory, cpu = memory_limit(size), int(limit) + 1
    t0 = time.perf_counter()
    if fork_server if fork_server is not None else hasattr(os, "fork"):
        how, raw = _SERVER.ask(library, spath, memory, cpu, limit)
        elapsed = time.perf_counter() - t0
        if how != "ok":
            what = "did not answer in time" if how == "timeout" else "died"
            return Lib3mfResult("timeout" if how == "timeout" else "crashed",
                                message=f"lib3mf's server process {what}", elapsed_s=elapsed)
        return _parse(raw, elapsed)
    try:
        proc = subprocess.run(worker_command(library, spath, memory, cpu), stdin=subprocess.DEVNULL,
                              capture_output=True, timeout=limit, check=False)
    except subprocess.TimeoutExpired:
        return Lib3mfResult("timeout", message=f"lib3mf did not finish within {limit:.0f} s",
                            elapsed_s=time.perf_counter() - t0)
    except OSError as exc:
        return Lib3mfResult("failed", message=f"cannot start the lib3mf worker: {exc.strerror or exc}")
    elapsed = time.perf_counter() - t0
    if proc.returncode < 0:
        sig = -proc.returncode
        try:
            signame = signal.Signals(sig).name
        except ValueError:
            signame = f"signal {sig}"
        status = "timeout" if sig == getattr(signal, "SIGXCPU", -1) else "crashed"
        return Lib3mfResult(status, message=f"lib3mf's process ended with {signame}", elapsed_s=elapsed)
    res = _parse(proc.stdout, elapsed)
    if res.status == "crashed":
        tail = proc.stderr[-300:].decode("utf-8", "replace").strip().splitlines()
        why = tail[-1] if tail else f"exit status {proc.returncode}"
        res.status = "memory" if "MemoryError" in why or "bad_alloc" in why else "crashed"
        res.message = f"lib3mf's process gave no verdict ({why[:200]})"
    return res


#: lib3mf messages that say nothing about the file
_UNINFORMATIVE = ("unknown error", "generic exception", "")


def lib3mf_findings(path: str | os.PathLike[str], notes: list[Finding]) -> list[Finding]:
    """Findings from lib3mf's verdict on ``path``, given the reader's own ``notes`` (to avoid double reports)."""
    res = run_lib3mf(path)
    who = f"lib3mf {res.version}".strip() if res.version else "lib3mf"
    own_errors = sum(1 for f in notes if f.code == "spec_violation" and f.severity == "error")
    if res.status == "unavailable":
        return [finding("lib3mf_not_run", f"the reference reader did not run: {res.message}; the file was checked "
                                          "by the checker's own 3MF rules only")]
    if res.status in ("timeout", "crashed", "memory", "failed"):
        why = {"timeout": "ran out of time", "crashed": "crashed", "memory": "ran out of memory",
               "failed": "could not run"}[res.status]
        return [finding("lib3mf_not_run", f"{who}, the reference reader, {why} on this file ({res.message}); printer "
                                          "software built on it may fail the same way. The checker's own rules "
                                          "still apply", severity="warning")]
    if res.status == "rejected" and "could not be opened" in res.message.lower():  # gone, or unreadable to us
        return [finding("lib3mf_not_run", f"{who} could not open the file ({res.message}); the checker's own rules "
                                          "still apply", severity="warning")]
    out: list[Finding] = []
    if res.status == "rejected":
        said = res.message.strip()
        text = (f"{who} (the 3MF Consortium's reader) refuses the file: {said!r}" if said.lower() not in _UNINFORMATIVE
                else f"{who} (the 3MF Consortium's reader) refuses the file without saying why (its message: "
                     f"{said or 'none'!r})")
        if own_errors:
            out.append(finding("lib3mf_rejects", text + "; the spec_violation findings say what to fix",
                               severity="info"))
        else:
            out.append(finding("lib3mf_rejects", text + "; printer software built on it will refuse it too"))
    if res.warnings:
        first = "; ".join(dict.fromkeys(m for _, m in res.warnings))[:300]
        more = f" ({res.warning_count} in all)" if res.warning_count > 1 else ""
        text = f"{who} warns{more}: {first}; in strict mode it refuses the file"
        if res.status == "rejected" or own_errors:
            out.append(finding("lib3mf_warning", text, severity="info"))
        else:
            out.append(finding("lib3mf_warning", text))
    if res.status == "read" and not res.warnings:
        out.append(finding("lib3mf_reads", f"{who} (the 3MF Consortium's reader) reads the file in strict mode"))
    return out
