"""Running the exporters, and the one place that writes the output folder.

The formats and their writers are rows of :data:`saucerfab.files.formats.TABLE`;
each writer is a pure function ``(TexturedMesh, FabOptions) -> {file name: bytes}``.
:func:`write_folder` writes all of them, plus ``scene.json`` and
``export.json``, as one folder via :func:`saucerfab.files.fileio.atomic_dir`: the
folder appears complete or not at all.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from saucerfab.errors import ExportError
from saucerfab.fabricate.options import FabOptions
from saucerfab.fabricate.textured import TexturedMesh
from saucerfab.files.fileio import atomic_dir
from saucerfab.files.formats import WRITERS, lookup

#: the subfolder of an export that holds the files of formats the printer does not take, written on
#: request (``allow_other=True``, ``saucerfab export --allow-format``): outside the print set, so every
#: file a bureau finds at the folder's top level is one its printer takes
OTHER_FORMATS_DIR = "other-formats"


def normalize_formats(
    formats: Sequence[str], accepted: Sequence[str], printer_name: str, allow_other: bool = False
) -> tuple[list[str], list[str]]:
    """Lower-cased, de-duplicated formats in the given order, each known; split by what the printer takes.

    One rule: a known format that ``accepted`` (the printer profile's list)
    lacks is refused before anything is written, unless ``allow_other``;
    then it is written outside the print set, into :data:`OTHER_FORMATS_DIR`
    (a GLB to share a preview, say), and checked without the printer's
    format list.

    Returns:
        ``(print_formats, other_formats)``: the formats the printer takes, and
        the others asked for (empty unless ``allow_other``), each in the given order.

    Raises:
        ExportError: an unknown format, none given, or a format the printer
            does not take without ``allow_other``.
    """
    out: list[str] = []
    for f in formats:
        found = lookup(f)
        if found is None or found.key not in WRITERS:
            raise ExportError(f"unknown export format {f!r}; known: {', '.join(WRITERS)}")
        if found.key not in out:
            out.append(found.key)
    if not out:
        raise ExportError("no export format given; name at least one, e.g. --formats 3mf")
    others = [k for k in out if k not in accepted]
    if others and not allow_other:
        raise ExportError(
            f"{printer_name} does not take {', '.join(o.upper() for o in others)} (its profile lists "
            f"{', '.join(accepted)}); give formats it takes, or (saucerfab export) add --allow-format to write "
            f"{'it' if len(others) == 1 else 'them'} anyway into {OTHER_FORMATS_DIR}/, outside the print set"
        )
    taken = [k for k in out if k in accepted]
    if not taken:  # an export is a print set first: other formats come beside it, never instead
        raise ExportError(
            f"{printer_name} takes none of {', '.join(o.upper() for o in others)}, so the print set would be "
            f"empty; add a format it takes (its profile lists {', '.join(accepted)})"
        )
    return taken, others


def render(mesh: TexturedMesh, fmt: str, options: FabOptions) -> dict[str, bytes]:
    """The files of one format (a key of :data:`~saucerfab.files.formats.WRITERS`), in memory."""
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
    """Write ``files`` (flat names, or ``other-formats/<name>``) as the folder ``out``, atomically.

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
                sub, _, base = name.rpartition("/")
                if sub not in ("", OTHER_FORMATS_DIR) or "\\" in base or not base or base.startswith("."):
                    raise ExportError(f"internal error: bad output file name {name!r}")
                (tmp / sub).mkdir(exist_ok=True)
                (tmp / name).write_bytes(data)
    except OSError as exc:
        raise ExportError(f"cannot write {str(path)!r}: {exc}") from None
    return path
