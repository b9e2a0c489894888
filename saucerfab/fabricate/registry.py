"""Running the exporters, and the one place that writes the output folder.

The formats and their writers are rows of :data:`saucerfab.formats.TABLE`;
each writer is a pure function ``(TexturedMesh, FabOptions) -> {file name: bytes}``.
:func:`write_folder` writes all of them, plus ``scene.json`` and
``export.json``, as one folder via :func:`saucerfab.fileio.atomic_dir`: the
folder appears complete or not at all.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from saucerfab.errors import ExportError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh
from saucerfab.fileio import atomic_dir
from saucerfab.formats import WRITERS, lookup


def normalize_formats(
    formats: Sequence[str], accepted: Sequence[str], printer_name: str
) -> tuple[list[str], list[str]]:
    """Lower-cased, de-duplicated formats in the given order, each known; and warnings.

    A known format that ``accepted`` (the printer profile's list) lacks is
    kept, with a warning: the designer may want it for something else (a GLB
    to share a preview), and the profile may be behind the printer's software.

    Returns:
        ``(formats, warnings)``: the formats to write, and one line per
        format the profile does not list.

    Raises:
        ExportError: an unknown format, or none given.
    """
    out: list[str] = []
    warnings: list[str] = []
    for f in formats:
        found = lookup(f)
        if found is None or found.key not in WRITERS:
            raise ExportError(f"unknown export format {f!r}; known: {', '.join(WRITERS)}")
        key = found.key
        if key in out:
            continue
        out.append(key)
        if key not in accepted:
            warnings.append(
                f"{printer_name}'s profile does not list {key!r}; written anyway "
                f"(check that the printer takes it; the profile lists {', '.join(accepted)})"
            )
    if not out:
        raise ExportError("no export format given; name at least one, e.g. --formats 3mf")
    return out, warnings


def render(mesh: TexturedMesh, fmt: str, options: FabOptions) -> dict[str, bytes]:
    """The files of one format (a key of :data:`~saucerfab.formats.WRITERS`), in memory."""
    return WRITERS[fmt].load_writer()(mesh, options)


def merge_files(per_format: Mapping[str, Mapping[str, bytes]], extra: Mapping[str, bytes]) -> dict[str, bytes]:
    """All files of all formats in one name -> bytes map.

    Formats may share a file (OBJ and VRML both put the atlas PNG beside
    them); a shared name must then hold the same bytes.
    """
    files: dict[str, bytes] = {}
    for group in (*per_format.values(), extra):
        for name, data in group.items():
            if name in files and files[name] != data:
                raise ExportError(f"internal error: two exporters write different {name!r}")
            files[name] = data
    return files


def write_folder(out: str | os.PathLike[str], files: Mapping[str, bytes]) -> Path:
    """Write ``files`` (flat names) as the folder ``out``, atomically.

    An existing ``out`` is replaced only if it is empty or a previous export
    (it holds ``export.json``), so a typo cannot wipe an unrelated folder.

    Raises:
        ExportError: ``out`` is a file, or a non-empty folder that is not an export.
    """
    path = Path(out)
    if path.exists():
        if not path.is_dir():
            raise ExportError(f"output {str(path)!r} exists and is not a folder; choose another --out")
        if any(path.iterdir()) and not (path / "export.json").is_file():
            raise ExportError(
                f"output folder {str(path)!r} is not empty and is not a saucerfab export; "
                "choose a new or empty folder"
            )
    try:
        with atomic_dir(path) as tmp:  # which gives the folder the usual mode (umask applies)
            for name, data in files.items():
                if "/" in name or "\\" in name or name.startswith("."):
                    raise ExportError(f"internal error: bad output file name {name!r}")
                (tmp / name).write_bytes(data)
    except OSError as exc:
        raise ExportError(f"cannot write {str(path)!r}: {exc}") from None
    return path
