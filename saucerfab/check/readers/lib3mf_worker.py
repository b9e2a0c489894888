"""Child process of the lib3mf stage: one 3MF through lib3mf's reader, the verdict as one JSON line.

Run by :mod:`saucerfab.check.readers.lib3mf_strict`, never imported by the
checker itself, either as a fork server (:func:`serve`, where the platform
can fork: lib3mf is loaded once and each file is read in a forked child) or
once per file::

    python -I -S lib3mf_worker.py --serve LIBRARY
    python -I -S lib3mf_worker.py LIBRARY FILE MEMORY_BYTES CPU_SECONDS

It uses only the standard library (``ctypes``) and binds the handful of
lib3mf C functions it needs directly, so a fresh child starts in ~30-40 ms rather
than the ~100 ms that importing lib3mf's generated Python bindings takes
(7,000 lines; the check runs once per 3MF, also on every export). The
process that reads a file limits itself first: address space
(``RLIMIT_AS``, where the platform has it), CPU seconds, and no core dumps;
a wall-clock timeout kills it (the server's, or the parent's).

lib3mf reads in its default (non-strict) mode: a fatal error ends the read,
and every issue it would refuse in strict mode is a recorded warning (strict
mode only makes the first warning fatal: ``CReader::SetStrictModeActive``
lowers the critical warning level to ``mrwInvalidOptionalValue``, the
lowest there is), so one read gives both verdicts. Messages come from
``lib3mf_getlasterror`` on the reader that failed, in a process that has
read nothing else, so they cannot be stale.

Output (stdout, one line, a Python literal: ``json`` would import ``re``,
20 ms of the child's start)::

    {"status": "read" | "rejected" | "memory" | "failed",
     "version": "2.5.0", "code": int | null, "message": str | null,
     "warnings": [[code, message], ...], "warning_count": int}
"""

from __future__ import annotations

import ctypes
import os
import sys

MAX_WARNINGS = 20


def _limit(memory: int, cpu: int) -> None:
    try:
        import resource
    except ImportError:  # not on this platform: the parent's timeout still applies
        return
    for name, value in (("RLIMIT_AS", memory), ("RLIMIT_CPU", cpu), ("RLIMIT_CORE", 0)):
        lim = getattr(resource, name, None)
        if lim is None or (value <= 0 and name != "RLIMIT_CORE"):
            continue
        try:
            resource.setrlimit(lim, (value, value))
        except (ValueError, OSError):
            pass


def _bind(lib: ctypes.CDLL) -> None:
    vp, u32, u64, cp = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_uint64, ctypes.c_char_p
    sigs = {
        "lib3mf_getlibraryversion": [ctypes.POINTER(u32)] * 3,
        "lib3mf_createmodel": [ctypes.POINTER(vp)],
        "lib3mf_release": [vp],
        "lib3mf_getlasterror": [vp, u64, ctypes.POINTER(u64), cp, ctypes.POINTER(ctypes.c_bool)],
        "lib3mf_model_queryreader": [vp, cp, ctypes.POINTER(vp)],
        "lib3mf_reader_setstrictmodeactive": [vp, ctypes.c_bool],
        "lib3mf_reader_readfromfile": [vp, cp],
        "lib3mf_reader_readfrombuffer": [vp, u64, ctypes.POINTER(ctypes.c_uint8)],
        "lib3mf_reader_getwarningcount": [vp, ctypes.POINTER(u32)],
        "lib3mf_reader_getwarning": [vp, u32, ctypes.POINTER(u32), u64, ctypes.POINTER(u64), cp],
    }
    for name, args in sigs.items():
        fn = getattr(lib, name)
        fn.restype = ctypes.c_int32
        fn.argtypes = args


def _last_error(lib: ctypes.CDLL, handle: ctypes.c_void_p) -> str:
    need = ctypes.c_uint64(0)
    has = ctypes.c_bool(False)
    if lib.lib3mf_getlasterror(handle, 0, ctypes.byref(need), None, ctypes.byref(has)) != 0 or not has.value:
        return ""
    buf = ctypes.create_string_buffer(max(int(need.value), 1))
    lib.lib3mf_getlasterror(handle, need.value, ctypes.byref(need), buf, ctypes.byref(has))
    return buf.value.decode("utf-8", "replace")


def _warnings(lib: ctypes.CDLL, reader: ctypes.c_void_p) -> tuple[int, list[list[object]]]:
    n = ctypes.c_uint32(0)
    if lib.lib3mf_reader_getwarningcount(reader, ctypes.byref(n)) != 0:
        return 0, []
    out: list[list[object]] = []
    for i in range(min(int(n.value), MAX_WARNINGS)):
        code, need = ctypes.c_uint32(0), ctypes.c_uint64(0)
        if lib.lib3mf_reader_getwarning(reader, i, ctypes.byref(code), 0, ctypes.byref(need), None) != 0:
            break
        buf = ctypes.create_string_buffer(max(int(need.value), 1))
        lib.lib3mf_reader_getwarning(reader, i, ctypes.byref(code), need.value, ctypes.byref(need), buf)
        out.append([int(code.value), buf.value.decode("utf-8", "replace")[:300]])
    return int(n.value), out


def load(library: str) -> ctypes.CDLL:
    lib = ctypes.CDLL(library)
    _bind(lib)
    return lib


def read(lib: ctypes.CDLL, path: str) -> dict[str, object]:
    """lib3mf's verdict on one file (the library already loaded)."""
    ver = [ctypes.c_uint32(0) for _ in range(3)]
    lib.lib3mf_getlibraryversion(*[ctypes.byref(v) for v in ver])
    result: dict[str, object] = {"version": ".".join(str(v.value) for v in ver), "code": None, "message": None,
                                 "warnings": [], "warning_count": 0}
    model, reader = ctypes.c_void_p(), ctypes.c_void_p()
    if lib.lib3mf_createmodel(ctypes.byref(model)) != 0 or not model.value:
        return {**result, "status": "failed", "message": "lib3mf could not create a model"}
    if lib.lib3mf_model_queryreader(model, b"3mf", ctypes.byref(reader)) != 0 or not reader.value:
        return {**result, "status": "failed", "message": _last_error(lib, model) or "no 3MF reader"}
    lib.lib3mf_reader_setstrictmodeactive(reader, False)
    name = os.fsencode(path)
    try:
        name.decode("utf-8")
        rc = lib.lib3mf_reader_readfromfile(reader, name)
    except UnicodeDecodeError:  # lib3mf takes UTF-8 names: hand it the bytes instead
        with open(path, "rb") as fh:
            data = fh.read()
        arr = (ctypes.c_uint8 * len(data)).from_buffer_copy(data)
        rc = lib.lib3mf_reader_readfrombuffer(reader, len(data), arr)
    count, warns = _warnings(lib, reader)
    result["warnings"], result["warning_count"] = warns, count
    if rc != 0:
        msg = _last_error(lib, reader)
        low = msg.lower()
        memory = "bad_alloc" in low or "out of memory" in low or ("memory" in low and "alloc" in low)
        result.update(status="memory" if memory else "rejected", code=int(rc), message=msg[:300])
    else:
        result["status"] = "read"
    lib.lib3mf_release(reader)
    lib.lib3mf_release(model)
    return result


def _guarded(lib: ctypes.CDLL | None, library: str, path: str) -> dict[str, object]:
    try:
        return read(lib if lib is not None else load(library), path)
    except MemoryError:
        return {"status": "memory", "message": "the child process ran out of its memory limit"}
    except (OSError, AttributeError) as exc:  # the library will not load (in too little memory too), or lacks a function
        text = f"{type(exc).__name__}: {exc}"[:300]
        memory = "failed to map" in text or "cannot allocate memory" in text.lower()
        return {"status": "memory" if memory else "failed", "message": text}


def serve(library: str) -> int:
    """Fork server: load lib3mf once, then read each requested file in a forked child with its own limits.

    Requests on stdin, one per line: ``<path as hex of its bytes> <memory bytes> <cpu s> <timeout s>``;
    one reply per request on stdout (the same literal as :func:`main`'s, or
    ``{"status": "timeout" | "crashed", "message": ...}``). A fork costs
    ~1 ms where a fresh interpreter with lib3mf costs ~30-40 ms, and each file
    still gets its own process: its crash, hang or memory blow-up ends that
    child only. The server ends at end of input.
    """
    import select
    import signal
    import time

    try:
        lib: ctypes.CDLL | None = load(library)
    except (OSError, AttributeError):
        lib = None  # each child tries again and reports why
    for line in sys.stdin:
        try:
            hexpath, memory, cpu, timeout = line.split()
            path = os.fsdecode(bytes.fromhex(hexpath))
            memory_i, cpu_i, deadline = int(memory), int(cpu), time.monotonic() + float(timeout)
        except ValueError:
            out: dict[str, object] = {"status": "failed", "message": "bad request to the lib3mf server"}
            sys.stdout.write(repr(out) + "\n")
            sys.stdout.flush()
            continue
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: limits, one read, the verdict down the pipe
            try:
                os.close(r)
                _limit(memory_i, cpu_i)
                data = repr(_guarded(lib, library, path)).encode()
                while data:
                    data = data[os.write(w, data):]
            finally:
                os._exit(0)
        os.close(w)
        chunks: list[bytes] = []
        timed_out = False
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                timed_out = True
                break
            ready, _, _ = select.select([r], [], [], left)
            if ready:
                chunk = os.read(r, 1 << 16)
                if not chunk:
                    break
                chunks.append(chunk)
        os.close(r)
        if timed_out:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        _, status = os.waitpid(pid, 0)
        if timed_out:
            out = {"status": "timeout", "message": f"lib3mf did not finish within {timeout} s"}
        elif os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            try:
                name = signal.Signals(sig).name
            except ValueError:
                name = f"signal {sig}"
            out = {"status": "timeout" if sig == getattr(signal, "SIGXCPU", -1) else "crashed",
                   "message": f"lib3mf's process ended with {name}"}
        else:
            text = b"".join(chunks).decode("utf-8", "replace").strip()
            if not text:
                out = {"status": "crashed", "message": f"lib3mf's process gave no verdict (exit status "
                                                       f"{os.WEXITSTATUS(status) if os.WIFEXITED(status) else status})"}
            else:
                sys.stdout.write(text.replace("\n", " ") + "\n")
                sys.stdout.flush()
                continue
        sys.stdout.write(repr(out) + "\n")
        sys.stdout.flush()
    return 0


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[1] == "--serve":
        return serve(argv[2])
    library, path, memory, cpu = argv[1], argv[2], int(argv[3]), int(argv[4])
    _limit(memory, cpu)
    sys.stdout.write(repr(_guarded(None, library, path)) + "\n")  # a Python literal: read with ast.literal_eval
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
