"""The ``saucerfab`` command line: ``main(argv)`` is testable in-process.

Each subcommand lives in its own module ``saucerfab.cli.<name>`` exposing

* ``HELP: str``                      one line for ``saucerfab --help``
* ``add_arguments(parser) -> None``  its options
* ``run(args) -> int``               the work; returns the exit code

Modules are imported only when their subcommand runs (``--help`` imports
each module for its arguments, but never torch), so ``saucerfab check``
starts without importing torch.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys
import time
from collections.abc import Sequence

from saucerfab import __version__
from saucerfab.errors import SaucerfabError

#: subcommand name -> module under saucerfab.cli (keep sorted by pipeline order)
SUBCOMMANDS: dict[str, str] = {
    "design": "design",
    "export": "export",
    "verify": "verify",
    "check": "check",
    "batch": "batch",
    "printers": "printers",
    "shapes": "shapes",
    "scene": "scene",
    "studio": "studio",
}


def _available() -> dict[str, object]:
    """Every subcommand's module, by subcommand name."""
    return {name: importlib.import_module(f"saucerfab.cli.{mod}") for name, mod in SUBCOMMANDS.items()}


def version_text() -> str:
    """saucerfab, Python and torch versions, and the compute device in use (torch's; "none" without torch)."""
    import platform

    from saucerfab.extras import installed, pip_line

    head = [f"saucerfab {__version__}", f"Python {platform.python_version()}"]
    if not installed("torch"):  # the checker's install (no 'design' extra): the versions still print
        return "\n".join(head + [f"torch not installed (design and export need it: {pip_line('design')})",
                                 "device none (the checker runs on the CPU without torch)"])
    import torch

    gpu = torch.cuda.is_available()
    dev = f"GPU ({torch.cuda.get_device_name(0)})" if gpu else "CPU (no CUDA GPU found)"
    return "\n".join(head + [f"torch {torch.__version__}", f"device {dev}"])


class _VersionAction(argparse.Action):
    def __init__(self, option_strings, dest, **kw):  # type: ignore[no-untyped-def]
        super().__init__(option_strings, dest, nargs=0, help="show versions and the device, then exit")

    def __call__(self, parser, namespace, values, option_string=None):  # type: ignore[no-untyped-def]
        print(version_text())
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="saucerfab",
        description="Design and fabricate mirror cup and saucer art.",
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, mod in _available().items():
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)  # type: ignore[attr-defined]
        mod.add_arguments(p)  # type: ignore[attr-defined]
        p.set_defaults(_run=mod.run)  # type: ignore[attr-defined]
    return parser


def _stdout_reader_gone() -> bool:
    """Whether stdout is a pipe whose reader has closed it (``saucerfab ... | head -1``)."""
    try:
        import select

        poller = select.poll()  # not on Windows: there the error is reported as usual
        poller.register(sys.stdout.fileno(), select.POLLOUT)
    except (AttributeError, OSError, ValueError):  # no poll, or stdout is not a file (captured)
        return False
    return any(events & select.POLLERR for _, events in poller.poll(0))


def _stdout_to_devnull() -> None:
    """Point stdout's descriptor at devnull, so the flush at exit cannot fail again.

    The recipe of Python's ``signal`` documentation (note on SIGPIPE).
    """
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    started = time.perf_counter()  # a subcommand reports its times from here (design: the first look)
    parser = build_parser()
    try:
        args = parser.parse_args(list(argv) if argv is not None else None)
    except BrokenPipeError:  # --version into a closed pipe (argparse guards its help itself)
        if not _stdout_reader_gone():
            raise
        _stdout_to_devnull()
        return 0
    if not getattr(args, "_run", None):
        parser.print_help()
        return 0
    args._started = started
    code: int | None = None
    try:
        code = int(args._run(args))
        sys.stdout.flush()  # a reader that has gone shows here, not at exit
        return code
    except SaucerfabError as exc:
        print(f"saucerfab {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # a bad output path, a full disk, no permission
        if isinstance(exc, BrokenPipeError) and _stdout_reader_gone():  # `| head -1`: quietly
            _stdout_to_devnull()
            return 0 if code is None else code
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(f"saucerfab {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"saucerfab {args.command}: interrupted", file=sys.stderr)
        return 130


def entry() -> None:  # console script (and ``python -m saucerfab``)
    """Run :func:`main` on the process's arguments and exit with its code.

    The objects left when a command ends are frozen out of the cyclic garbage
    collector first (:func:`gc.freeze`): Python's shutdown would otherwise scan
    every one of them (about 290,000 after a design: torch, numba, Mitsuba),
    which took 0.9 s of the 1.1 s between the end of a design and the end of its
    process. The process's memory goes back to the system as a whole; the
    shutdown itself (atexit handlers, threads joined, modules and files closed)
    runs as before. Only here, after :func:`main` has returned, and not in
    :func:`main` itself: a process that calls it and goes on (the tests) keeps
    its collector as it was, and a long-lived command (``studio``, ``batch``)
    runs with the collector as usual until its way out.
    """
    code = main()
    gc.freeze()
    sys.exit(code)
