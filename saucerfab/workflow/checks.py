"""The workflow's check step: every mesh file an export wrote, checked as the bureau will read it.

:func:`check_export` is the one check loop of every front door (``saucerfab
export``, ``saucerfab batch``, the studio): which files hold a mesh
(:func:`meshes_to_check`, a zipped OBJ unpacked), the limits raised to the
export's own sizes (:func:`export_limits`), and the printer only for the
files of the print set. :func:`check_json` is the ``check.json`` document an
export folder keeps (schema ``saucerfab.check/1``, no times, so the folder
is reproducible).
"""

from __future__ import annotations

import contextlib
import json
import tempfile
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: the schema of an export folder's check.json
CHECK_SCHEMA = "saucerfab.check/1"


@dataclass(frozen=True)
class MeshToCheck:
    """One mesh file an export wrote, as the checker should read it.

    Attributes:
        written: the file in the export folder (the mesh file, or the zip holding it).
        name: how reports name it: the file's name, or ``<zip>/<entry>`` for a mesh inside a zip.
        path: the file to check (a zip's entry unpacked into a scratch folder).
    """

    written: Path
    name: str
    path: Path


@dataclass(frozen=True)
class CheckedFile:
    """One checked mesh file of an export.

    Attributes:
        written: the file in the export folder (a zipped OBJ: its zip).
        name: the mesh's name as :class:`MeshToCheck` gives it (``<zip>/<entry>`` inside a zip).
        report: the checker's :class:`~saucerfab.check.Report`, or None where the checker is absent.
    """

    written: Path
    name: str
    report: Any


@contextlib.contextmanager
def meshes_to_check(files: Mapping[str, Sequence[Path]], scratch: Path | None = None) -> Iterator[list[MeshToCheck]]:
    """The mesh files of an export (format -> its written files), unpacked where zipped; for the ``with`` block.

    Which files hold a mesh is :func:`saucerfab.files.formats.files_to_check`'s
    answer. A zipped OBJ (``FabOptions.obj_zip``) is checked as what the
    bureau unpacks: the archive's entries go to a temporary folder (under
    ``scratch`` when given), removed when the block ends, and its mesh entry
    is checked with the MTL and PNG beside it.

    Raises:
        ExportError: a format wrote no mesh file, or its zip holds an entry
            that is not a plain file name (the export wrote it: an internal error).
    """
    from saucerfab.errors import ExportError
    from saucerfab.files.formats import TABLE, files_to_check

    with tempfile.TemporaryDirectory(prefix="saucerfab-check-", dir=scratch) as tmp:
        out: list[MeshToCheck] = []
        for fmt, paths in files.items():
            suffix = TABLE[fmt].mesh_suffix
            by_name = {p.name: p for p in paths}
            found = []
            for name in files_to_check(fmt, list(by_name)):
                written = by_name[name]
                if not name.lower().endswith(".zip"):
                    found.append(MeshToCheck(written, name, written))
                    continue
                dest = Path(tmp) / name
                with zipfile.ZipFile(written) as zf:
                    for info in zf.infolist():
                        entry = info.filename
                        if info.is_dir() or "/" in entry or "\\" in entry or entry.startswith(".") or not entry:
                            raise ExportError(f"the export's {name} holds an unexpected entry {entry!r}")
                        dest.mkdir(parents=True, exist_ok=True)
                        (dest / entry).write_bytes(zf.read(info))
                        if entry.lower().endswith(suffix):
                            found.append(MeshToCheck(written, f"{name}/{entry}", dest / entry))
            if not found:
                raise ExportError(f"the export wrote no {suffix} file for format {fmt!r}")
            out += found
        yield out


def export_limits(result: Any) -> Any:
    """The checker's limits for the files an export wrote: the defaults, raised to what the export holds.

    The default :class:`~saucerfab.check.Limits` are budgets against a
    stranger's hostile file (at most 10 s and 1 GiB per file, so 500,000
    triangles and one 8192 x 8192 texture). These files are saucerfab's own,
    written a moment ago from the design: a design at the largest grid
    (``scene.MAX_GRID``) exports millions of triangles and a 16384 px atlas,
    and the product must not refuse its own print as "too large to check".
    So the triangle, vertex, byte and texture caps are raised to the
    export's own sizes (never lowered); the checks then cost what a mesh of
    that size costs (~1 GB and ~15 s per million triangles).
    """
    from saucerfab.check.limits import DEFAULT_LIMITS, inflated_bytes

    paths = [Path(p) for ps in result.files.values() for p in ps]
    sizes = [p.stat().st_size for p in paths if p.is_file()]
    return DEFAULT_LIMITS.raised_to(
        triangles=int(result.triangles),
        texture_px=int(result.texture_px),
        file_bytes=max(sizes, default=0),
        inflated_bytes=inflated_bytes(paths),
    )


def check_mesh_file(path: Path, profile: Any, limits: Any = None) -> Any | None:
    """``saucerfab.check.check_mesh(path, printer=profile, limits=limits)``, or None where the checker is absent."""
    try:
        from saucerfab.check import check_mesh
    except ImportError:
        return None
    return check_mesh(path, printer=profile, limits=limits)


def check_export(result: Any, profile: Any, *, scratch: Path | None = None) -> list[CheckedFile]:
    """Check every mesh file of an export (``result``: its :class:`~saucerfab.fabricate.pipeline.ExportResult`).

    The files are the product's own: checked within limits raised to the
    export's sizes (:func:`export_limits`), not the hostile-file defaults. A
    file outside the print set (a format the printer does not take, written
    on request into a subfolder) is checked without ``profile``: it is not
    for that printer. ``scratch``: where a zipped OBJ is unpacked (a
    temporary folder under it, removed afterwards; default the system's).
    """
    folder = Path(result.out)
    try:
        limits = export_limits(result)
    except ImportError:
        limits = None  # no checker installed: check_mesh_file says so per file
    with meshes_to_check(result.files, scratch=scratch) as meshes:
        return [CheckedFile(m.written, m.name,
                            check_mesh_file(m.path, profile if m.written.parent == folder else None, limits))
                for m in meshes]


def check_json(folder: Path, checks: Sequence[CheckedFile]) -> str:
    """The text of an export folder's ``check.json``: each report without times, named relative to ``folder``.

    A zipped OBJ is named by its zip (the file written); files the checker
    could not check (absent) are left out.
    """
    docs = []
    for c in checks:
        if c.report is None:
            continue
        d = c.report.to_dict()
        d.pop("elapsed_s", None)  # the folder stays byte-identical run to run
        d["path"] = c.written.relative_to(folder).as_posix() if c.written.is_relative_to(folder) else c.written.name
        docs.append(d)
    return json.dumps({"schema": CHECK_SCHEMA, "files": docs}, indent=2, sort_keys=True) + "\n"
