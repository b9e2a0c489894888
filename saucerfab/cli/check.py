"""``saucerfab check FILE...``: will these meshes print? For people, CI systems and bureaus.

Exit code: 0 all printable, 1 some not printable, 2 some unreadable or not a
mesh (the largest over the files). A FILE may be a folder (every mesh file
directly in it: a print folder's print set) or a glob pattern (``'out/*.3mf'``,
for shells that do not expand it). On a terminal, a table; into a pipe or a
file, one line per file and one per finding, each starting with the file's
path (greppable); ``--json`` the schema ``saucerfab.check/1`` (``-o FILE``
and ``--junit FILE`` write it and JUnit XML to files, replacing an existing
file only with ``--force``); then a summary line (the only line with ``-q``).
This module imports nothing heavy at import time: ``saucerfab --help``
loads it, and ``saucerfab check`` must start fast without torch.
"""

from __future__ import annotations

import argparse
import sys

from saucerfab.cli.schema_flag import add_schema_flag, schema_asked
from saucerfab.files.formats import READERS, labels

HELP = f"check mesh files ({labels(READERS.values())}) for printability; exit 0/1/2"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("files", nargs="*", metavar="FILE",
                   help="mesh files to check; a folder checks every mesh file directly in it, a quoted glob "
                        "pattern ('out/*.3mf') the files it matches")
    p.add_argument("--printer", metavar="NAME", help="check against a printer profile (key or .toml path)")
    p.add_argument("--json", action="store_true", help="print the saucerfab.check/1 JSON document instead of a table")
    p.add_argument("--junit", metavar="FILE", help="also write a JUnit XML report to FILE")
    p.add_argument("-o", "--out", metavar="FILE", help="also write the saucerfab.check/1 JSON document to FILE")
    p.add_argument("--force", action="store_true", help="replace an existing --out or --junit file")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the summary line")
    p.add_argument("--strict", action="store_true", help="warnings fail too (exit 1)")
    p.add_argument("--max-triangles", type=int, metavar="N",
                   help="check files of up to N triangles (default 500,000; larger files are refused as too large "
                        "to check, exit 2); checking costs about 1 GB of memory and 15 s per million triangles, "
                        "so raise it only for files you trust")
    p.add_argument("--min-wall", type=float, metavar="MM",
                   help="warn about walls under MM when no --printer gives a minimum")
    add_schema_flag(p)


def _keep_freed_memory() -> None:
    """Let glibc keep freed blocks up to 32 MiB in the heap instead of unmapping them.

    A check allocates and frees hundreds of large temporary arrays; by
    default glibc hands each back to the kernel and faults it in again on
    the next allocation, which costs this short-lived process ~15% of its
    CPU on a 100,000-triangle file. Only the CLI does this (it owns its
    process); the library leaves the allocator alone. Best effort: not glibc,
    no change.
    """
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD (the most glibc allows on 64-bit)
        libc.mallopt(-1, 256 << 20)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass


#: most entries of a zip in a folder that are listed to see whether it holds a mesh (a bureau's zipped OBJ
#: holds three; a larger archive is passed to the checker, which judges it within its own limits)
MAX_ZIP_ENTRIES_LISTED = 1000


def _zip_holds_a_mesh(path: object) -> bool:
    """Whether a zip found in a folder holds a mesh file (its entry names only; nothing is unpacked).

    A zip that cannot be listed, or lists more than
    :data:`MAX_ZIP_ENTRIES_LISTED` entries, is kept: the checker reads it
    within its limits and says what is wrong with it.
    """
    import zipfile

    from saucerfab.files.formats import SUFFIXES

    try:
        with zipfile.ZipFile(path) as zf:  # type: ignore[arg-type]
            infos = zf.infolist()
    except (OSError, zipfile.BadZipFile, ValueError, RuntimeError):
        return True
    if len(infos) > MAX_ZIP_ENTRIES_LISTED:
        return True
    return any(i.filename.lower().endswith(tuple(SUFFIXES)) for i in infos)


def _folder_meshes(folder: object) -> list[str]:
    """The mesh files directly in ``folder``, sorted: a reader's suffix, or a zip holding a mesh."""
    from pathlib import Path

    from saucerfab.files.formats import SUFFIXES

    found = []
    for p in sorted(Path(folder).iterdir()):  # type: ignore[arg-type]
        suffix = p.suffix.lower()
        if p.is_file() and (suffix in SUFFIXES and suffix != ".zip" or suffix == ".zip" and _zip_holds_a_mesh(p)):
            found.append(str(p))
    return found


def expand_files(given: list[str]) -> list[str]:
    """The mesh files ``given`` names: files as they are, a folder's mesh files, a glob's matches; in order.

    A folder gives every file directly in it whose suffix a checker reader
    takes (:data:`saucerfab.files.formats.SUFFIXES`), and every ``.zip`` whose
    entries hold one (an OBJ zipped with its side files), sorted by name; not
    its subfolders (an export's print set is its top level). A name that does
    not exist and holds ``*``, ``?`` or ``[`` is a glob pattern: its matches,
    sorted, each a file or a folder as above. Anything else is passed on as it
    is, so a missing file is reported as unreadable like any other.

    Raises:
        ConfigError: a folder with no mesh file, or a pattern that matches nothing.
    """
    import glob
    from pathlib import Path

    from saucerfab.errors import ConfigError
    from saucerfab.files.formats import SUFFIXES

    def one(name: str) -> list[str]:
        if not Path(name).is_dir():
            return [name]
        found = _folder_meshes(name)
        if not found:
            raise ConfigError(f"folder {name!r} holds no mesh file ({', '.join(sorted(SUFFIXES))}, or a zip of one); "
                              "give the folder an export wrote, or the files themselves")
        return found

    out: list[str] = []
    for name in given:
        if not Path(name).exists() and glob.has_magic(name):
            matches = sorted(glob.glob(name))
            if not matches:
                raise ConfigError(f"no file matches {name!r}; check the pattern (quote it so the shell leaves it)")
            for m in matches:
                out += _folder_meshes(m) if Path(m).is_dir() else [m]  # a matched folder with no mesh: nothing
        else:
            out += one(name)
    return list(dict.fromkeys(out))  # a file named twice (a folder and a glob) is checked once


def on_terminal() -> bool:
    """Whether stdout is a terminal (a person reads the table) rather than a pipe or a file (a program does)."""
    try:
        return sys.stdout.isatty()
    except (AttributeError, ValueError):  # closed or replaced stdout
        return False


def run(args: argparse.Namespace) -> int:
    from saucerfab.check import JSON_SCHEMA, Limits, check_many, reports_to_json, reports_to_junit, summary_line
    from saucerfab.cli.outputs import refuse_existing
    from saucerfab.errors import ConfigError
    from saucerfab.files.fileio import write_text_atomic

    if schema_asked(args, JSON_SCHEMA, args.files, "give one or more mesh files to check (saucerfab check FILE...)"):
        return 0
    for option, path in (("--out", args.out), ("--junit", args.junit)):
        if path:
            refuse_existing(option, path, args.force)
    files = expand_files(args.files)
    changes: dict[str, object] = {}
    if args.max_triangles is not None:
        if args.max_triangles <= 0:
            raise ConfigError(f"--max-triangles must be positive, got {args.max_triangles}")
    if args.min_wall is not None:
        if not args.min_wall > 0:
            raise ConfigError(f"--min-wall must be positive millimetres, got {args.min_wall}")
        changes["min_wall_mm"] = args.min_wall
    limits = Limits()
    if args.max_triangles is not None:
        # the vertex and byte caps follow (an STL stores three vertices per triangle)
        limits = limits.for_triangles(args.max_triangles)
    limits = limits.with_(**changes)
    _keep_freed_memory()
    reports = check_many(files, printer=args.printer, limits=limits, strict=args.strict)
    for option, path, text in (("--junit", args.junit, reports_to_junit), ("--out", args.out, reports_to_json)):
        if not path:
            continue
        try:
            write_text_atomic(path, text(reports) + ("\n" if option == "--out" else ""))
        except OSError as exc:
            raise ConfigError(f"cannot write {option} {path!r}: {exc.strerror or exc}") from None
    code = max(r.exit_code for r in reports)
    try:
        if args.json:
            sys.stdout.write(reports_to_json(reports) + "\n")
            print(summary_line(reports), file=sys.stderr)
        elif args.quiet:
            print(summary_line(reports))
        elif on_terminal():
            from saucerfab.check.report import render_table

            render_table(reports)
            print(summary_line(reports))
        else:  # a pipe or a file: greppable lines, no table
            from saucerfab.check.report import render_plain

            render_plain(reports)
            print(summary_line(reports))
        sys.stdout.flush()
    except BrokenPipeError:
        # `check ... | head`: the reader has all it wanted; the verdict still decides the exit code
        from saucerfab.cli import _stdout_reader_gone, _stdout_to_devnull

        if not _stdout_reader_gone():
            raise
        _stdout_to_devnull()
    return code
