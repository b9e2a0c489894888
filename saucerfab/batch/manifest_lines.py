"""A manifest as text: reading it, the line of each thing in it, and the list of its problems.

:func:`read_manifest_text` and :func:`toml_loads` read the file within limits
(size, nesting). ``tomllib`` gives no positions, so :class:`TomlLines` finds
them with a light scan of the text: the ``[[job]]`` headers in order (the
n-th header is the n-th job), the ``[defaults]`` table, and the first line
of each key in them (``key = ...``, a dotted ``key.sub = ...`` or a
sub-table ``[job.key]``). The scan skips multi-line strings; a key it cannot
place falls back to the job's header line (and a job list written as an
inline ``job = [...]`` array to the line of ``job``). :func:`csv_records`
gives each CSV record with the line it starts on, comment lines skipped but
counted.

:func:`resolve_inside` and :func:`input_problem` judge a job's paths (inside
the manifest's folder; there, and readable). :class:`Problems` collects a
manifest's problems as ``file:line: job 'id': what``, each once
(:func:`reporter` places a job's problem at the line of its key, or of
``[defaults]`` when the job inherits the key), and turns them into one
:class:`ConfigError` that lists the first :data:`MAX_PROBLEMS_SHOWN`.
"""

from __future__ import annotations

import csv
import os
import re
import stat
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from saucerfab.errors import ConfigError

#: largest manifest file accepted (a manifest is text listing jobs)
MAX_MANIFEST_BYTES = 16 * 1024 * 1024
#: deepest nesting of arrays and tables a manifest may hold; a manifest needs 5
#: (the document, ``[[job]]``, a job, its ``design_options``, a list in it), and
#: neither the parser nor any later walk of the data may run out of stack
MAX_NESTING = 32
#: most problems one error lists; a 100,000-job manifest with one systematic
#: mistake would otherwise print megabytes (the rest are counted)
MAX_PROBLEMS_SHOWN = 50

#: a bare, "quoted" or 'literal' key at the start of a line, then '=' or a dot (a dotted key)
_KEY_RE = re.compile(r"""\s*(?:([A-Za-z0-9_-]+)|"([^"\\]*)"|'([^']*)')\s*[.=]""")
#: a table header: [name] or [[name]] (name possibly dotted), then nothing but a comment
_HEADER_RE = re.compile(r"\s*(\[\[?)\s*([^\[\]]+?)\s*\]\]?\s*(?:#.*)?$")


def _header_parts(name: str) -> list[str]:
    """``job . "design_options"`` -> ``["job", "design_options"]``."""
    return [p.strip().strip("\"'") for p in name.split(".")]


class TomlLines:
    """Line numbers (1-based) of a TOML manifest's jobs, ``[defaults]`` and top-level keys."""

    def __init__(self, text: str) -> None:
        #: per ``[[job]]`` header, in order: its line and the first line of each of its keys
        self.jobs: list[tuple[int, dict[str, int]]] = []
        self.defaults_keys: dict[str, int] = {}
        self.top_keys: dict[str, int] = {}
        section: dict[str, int] | None = self.top_keys  # where keys of the current table go (None: nowhere)
        closing: str | None = None  # the delimiter of the multi-line string being skipped
        for n, line in enumerate(text.splitlines(), start=1):
            if closing is not None:
                if closing in line:
                    closing = None
                continue
            header = _HEADER_RE.match(line)
            if header:
                double, parts = header.group(1) == "[[", _header_parts(header.group(2))
                self.top_keys.setdefault(parts[0], n)
                section = None
                if parts == ["job"] and double:
                    self.jobs.append((n, {}))
                    section = self.jobs[-1][1]
                elif parts == ["defaults"]:
                    section = self.defaults_keys
                elif parts[0] == "job" and self.jobs:  # [job.design_options]: a table of the last job
                    self.jobs[-1][1].setdefault(parts[1], n)
                elif parts[0] == "defaults":
                    self.defaults_keys.setdefault(parts[1], n)
                continue
            key = _KEY_RE.match(line)
            if key and section is not None:
                section.setdefault(next(g for g in key.groups() if g is not None), n)
            for delim in ('"""', "'''"):  # a multi-line string opened and not closed on this line
                if line.count(delim) % 2 == 1:
                    closing = delim
                    break

    def job(self, index: int, count: int, key: str | None = None) -> int | None:
        """The line of job ``index``'s ``key`` (None: of the job itself), ``count`` jobs in all.

        A key the job does not write itself gives the job's header line; jobs
        the scan cannot match to headers (an inline ``job = [...]``) give the
        line of ``job``.
        """
        if len(self.jobs) != count:
            return self.top_keys.get("job")
        header, keys = self.jobs[index]
        return keys.get(key, header) if key is not None else header

    def defaults(self, key: str | None = None) -> int | None:
        """The line of ``[defaults]``' ``key`` (None, or a key it does not write: of the table)."""
        top = self.top_keys.get("defaults")
        return self.defaults_keys.get(key, top) if key is not None else top


def csv_records(text: str) -> Iterator[tuple[int, list[str]]]:
    """``(line, cells)`` for each record of a CSV text; lines starting with ``#`` are
    comments, skipped but counted, so ``line`` is the file's own (1-based)."""
    origin: list[int] = []  # the file's line number of each line handed to the reader

    def uncommented() -> Iterator[str]:
        # line ends kept: the reader needs them inside a quoted cell that spans lines
        for n, line in enumerate(text.splitlines(keepends=True), start=1):
            if not line.lstrip().startswith("#"):
                origin.append(n)
                yield line

    reader = csv.reader(uncommented(), skipinitialspace=True)
    read = 0  # lines the reader had consumed before this record
    for cells in reader:
        start = origin[read] if read < len(origin) else len(origin)
        read = reader.line_num
        yield start, cells


class Problems:
    """A manifest's problems, each once, in the order found."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._found: dict[str, None] = {}  # a dict keeps the order and drops repeats

    def add(self, line: int | None, label: str, message: str) -> None:
        """Record ``message`` about ``label`` (``job 'teapot'``, ``[defaults]``; may be empty) at ``line``."""
        where = f"{self.path.name}:{line}" if line is not None else self.path.name
        self._found.setdefault(f"{where}: {label}: {message}" if label else f"{where}: {message}")

    def __len__(self) -> int:
        return len(self._found)

    def error(self) -> ConfigError:
        """One error listing the problems (the first :data:`MAX_PROBLEMS_SHOWN`, then a count)."""
        found = list(self._found)
        shown = found[:MAX_PROBLEMS_SHOWN]
        more = len(found) - len(shown)
        return ConfigError(
            f"manifest {str(self.path)!r} has {len(found)} problem(s); nothing was run "
            "(fix them and run again):\n  " + "\n  ".join(shown) + (f"\n  ... and {more} more" if more else "")
        )


def resolve_inside(root: Path, value: Any, where: str) -> Path:
    """``value`` (a relative path string) resolved against ``root``; refuse escapes.

    Raises:
        ConfigError: not a string, absolute, or resolving (``..``, symlinks) outside ``root``.
    """
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{where}: expected a relative path (a non-empty string), got {value!r}")
    p = Path(value)
    if p.is_absolute() or value.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", value):
        raise ConfigError(
            f"{where}: {value!r} is an absolute path; paths in a manifest are relative to its "
            f"folder {str(root)!r} and must stay inside it: move the file there and give it relative"
        )
    root_real = root.resolve()
    full = (root_real / p).resolve()
    if not full.is_relative_to(root_real):
        raise ConfigError(
            f"{where}: {value!r} resolves to {str(full)!r}, outside the manifest's folder "
            f"{str(root_real)!r}; manifest paths may not leave that folder (no '..' or links out): "
            "copy the file under it"
        )
    return full


def input_problem(path: Path, value: str, key: str) -> str | None:
    """Why the input ``path`` (written ``value`` for job key ``key``) cannot be used, or None.

    Checked when the manifest loads, for every job: the path exists, is a
    folder (``design``) or a file (images, ``shape``, ``scene``, a ``printer``
    file), and can be read. What is in it is the job's business, read when the
    job runs (a broken image fails that job alone).
    """
    what = {"design": "design folder", "shape": "shape file", "scene": "scene file",
            "printer": "printer profile file"}.get(key, f"{key} image")
    folder = key == "design"
    try:
        st = path.stat()
    except (FileNotFoundError, NotADirectoryError):
        return (f"{what} {value!r} not found (paths are relative to the manifest's folder): "
                f"check the name, or put the {'folder' if folder else 'file'} there")
    except OSError as exc:
        return f"{what} {value!r} cannot be read ({exc.strerror or exc}): let this user read it"
    if folder and not stat.S_ISDIR(st.st_mode):
        return f"{what} {value!r} is a file, not a folder: give the folder 'saucerfab design' wrote"
    if not folder and not stat.S_ISREG(st.st_mode):
        return f"{what} {value!r} is not a file: give the file itself"
    if not os.access(path, os.R_OK | (os.X_OK if folder else 0)):
        return f"{what} {value!r} cannot be read (no permission): let this user read it"
    return None


#: reports one problem of a job: (the job key it is about, None for the job as a whole; the message)
Report = Callable[[str | None, str], None]


#: one job as written: where its keys are (``key`` -> line; None: the job's own line) and its own keys
Row = tuple[Callable[[str | None], int | None], dict[str, Any]]


def job_label(job_id: Any, number: int) -> str:
    """How messages name a job: by its id when it has a usable one, else by its place."""
    return f"job {job_id!r}" if isinstance(job_id, str) and job_id.strip() else f"job #{number}"


def reporter(
    problems: Problems,
    own: dict[str, Any],
    defaults: dict[str, Any],
    locate: Callable[[str | None], int | None],
    defaults_line: Callable[[str | None], int | None],
    label: str,
) -> Report:
    """How one job's problems are recorded: at the line of the key they are about. A key
    the job inherits from ``[defaults]`` is that table's problem: listed once, at its line."""

    def report(key: str | None, message: str) -> None:
        if key is not None and key not in own and key in defaults:
            problems.add(defaults_line(key), "[defaults]", message)
        else:
            problems.add(locate(key), label, message)

    return report


def read_manifest_text(path: Path) -> str:
    """The text of the manifest ``path`` (UTF-8, a BOM allowed), at most :data:`MAX_MANIFEST_BYTES`.

    Raises:
        ConfigError: missing, too large or unreadable.
    """
    if not path.is_file():
        raise ConfigError(f"manifest {str(path)!r} not found")
    if path.stat().st_size > MAX_MANIFEST_BYTES:
        raise ConfigError(f"manifest {str(path)!r} is over {MAX_MANIFEST_BYTES >> 20} MB; split it")
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read manifest {str(path)!r}: {exc}") from None


def nesting_depth(value: Any) -> int:
    """How deeply arrays and tables nest in ``value`` (a scalar: 0), without recursion.

    Counting stops past :data:`MAX_NESTING`, so the answer is at most one more.
    """
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, dict):
            v = list(v.values())
        if isinstance(v, (list, tuple)):
            depth += 1
            deepest = max(deepest, depth)
            if depth <= MAX_NESTING:  # deeper is refused anyway: stop counting
                stack.extend((x, depth) for x in v)
    return deepest


def toml_loads(text: str, what: str) -> dict[str, Any]:
    """``tomllib.loads`` with a syntax error, or nesting too deep, as a :class:`ConfigError`.

    tomllib parses arrays and inline tables recursively: a file nesting a few
    thousand of them exhausts the stack (RecursionError), which is the file's
    fault, not a crash.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(
            f"{what} nests arrays or tables too deeply to be read; "
            f"a manifest needs at most {MAX_NESTING} levels: remove the nesting"
        ) from None
    if nesting_depth(data) > MAX_NESTING:
        raise ConfigError(
            f"{what} nests arrays or tables over {MAX_NESTING} levels deep; a manifest needs "
            "at most a few (a job's option table holds lists of numbers at most): remove the nesting"
        )
    return data
