"""After an export: check every written file, verify the print, write the print's report.

``saucerfab export`` (and ``saucerfab batch``) call :func:`finish_print` on
the folder :func:`~saucerfab.fabricate.pipeline.export_design` wrote:

1. ``check``: every mesh file (an OBJ zip is checked as what a bureau
   unpacks), results in ``check.json`` (schema ``saucerfab.check/1``, no
   times, so the folder is reproducible);
2. ``verify``: a quick ray trace of the first textured file from the design
   eye and a viewer's two eyes (:data:`QUICK_RES`, :data:`QUICK_SPP`),
   pictures and ``verify.json`` in ``verify/``;
3. ``report.html`` (:mod:`saucerfab.report_page`).

Each file is written atomically; a failure of step 2 or 3 never removes the
print files, and is reported as a note rather than raised, because the
print itself is complete and printable at that point.
"""

from __future__ import annotations

import contextlib
import json
import tempfile
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from saucerfab.profiles import DEFAULT_PRINTER

#: quick verify of every export: render size and samples per pixel
QUICK_RES = 128
QUICK_SPP = 4

#: atlas edge of the trial export a design's quick verify renders (:func:`verify_design`). At
#: QUICK_RES a view's frame spans 128 px, so 1024 texels across the saucer's top are several per
#: pixel; the printer's own atlas (4096 for a J55 at 600 dpi) costs a 16x larger bake and texture
#: load for the same picture (heart-star: 5.2 -> 2.1 s a quick verify,
#: benchmarks/results/HISTORY.md, "The quick verify of `saucerfab design`").
#: An export's own verify (:func:`finish_print`) always renders the atlas it wrote.
QUICK_TEXTURE_PX = 1024


@dataclass
class Finished:
    """What :func:`finish_print` did.

    Attributes:
        checks: (mesh file, check Report or None when the checker is absent).
        verify: the :class:`~saucerfab.verify.VerifyResult`, or None when skipped or failed.
        notes: what could not be done and why (verify or report failures).
    """

    checks: list[tuple[Path, Any]] = field(default_factory=list)
    verify: Any = None
    notes: list[str] = field(default_factory=list)

    @property
    def check_exit_code(self) -> int:
        return max([int(r.exit_code) for _, r in self.checks if r is not None], default=0)


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


@contextlib.contextmanager
def meshes_to_check(files: Mapping[str, Sequence[Path]], scratch: Path | None = None) -> Iterator[list[MeshToCheck]]:
    """The mesh files of an export (format -> its written files), unpacked where zipped; for the ``with`` block.

    Which files hold a mesh is :func:`saucerfab.formats.files_to_check`'s
    answer. A zipped OBJ (``FabOptions.obj_zip``) is checked as what the
    bureau unpacks: the archive's entries go to a temporary folder (under
    ``scratch`` when given), removed when the block ends, and its mesh entry
    is checked with the MTL and PNG beside it.

    Raises:
        ExportError: a format wrote no mesh file, or its zip holds an entry
            that is not a plain file name (the export wrote it: an internal error).
    """
    from saucerfab.errors import ExportError
    from saucerfab.formats import TABLE, files_to_check

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


def finish_print(
    result: Any,
    profile: Any,
    *,
    check: bool = True,
    verify: bool = True,
    record_times: bool = True,
    progress: Any = None,
) -> Finished:
    """Check, verify and report an export folder (see the module docstring).

    Args:
        result: the :class:`~saucerfab.fabricate.pipeline.ExportResult`.
        profile: the printer profile it was exported for.
        check, verify: run those steps.
        record_times: keep wall times in ``verify.json`` (batch turns them off).
        progress: ``progress(message, fraction)`` for the verify renders.
    """
    from saucerfab.fileio import atomic_dir, write_text_atomic

    folder = Path(result.out)
    done = Finished()
    if check:
        try:
            # the product's own files: checked within limits raised to the export's sizes, not the
            # hostile-file defaults (see export_limits)
            limits = export_limits(result)
        except ImportError:
            limits = None  # no checker installed: check_mesh_file says so per file
        with meshes_to_check(result.files) as meshes:
            # reported by the file written: a zipped OBJ is named by its zip. A file outside the print
            # set (a format the printer does not take, written on request into a subfolder) is checked
            # without the printer: it is not for that printer.
            done.checks += [(m.written, check_mesh_file(m.path, profile if m.written.parent == folder else None,
                                                        limits)) for m in meshes]
        docs = []
        for path, rep in done.checks:
            if rep is None:
                continue
            d = rep.to_dict()
            d.pop("elapsed_s", None)  # the folder stays byte-identical run to run
            d["path"] = path.relative_to(folder).as_posix() if path.is_relative_to(folder) else path.name
            docs.append(d)
        write_text_atomic(folder / "check.json", json.dumps({"schema": "saucerfab.check/1", "files": docs},
                                                            indent=2, sort_keys=True) + "\n")
    if verify:
        from saucerfab.errors import SaucerfabError
        from saucerfab.verify import verify_print

        try:
            with atomic_dir(folder / "verify") as tmp:
                res = verify_print(folder, res=QUICK_RES, spp=QUICK_SPP, pictures_dir=tmp, all_formats=False,
                                   progress=progress)
                doc = res.to_dict(record_times=record_times)
                doc["folder"] = "."  # relative: the folder may be moved or sent on
                (tmp / "verify.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
            done.verify = res
        except SaucerfabError as exc:
            done.notes.append(f"not verified: {exc}")
    try:
        from saucerfab.report_page import refresh_export_report

        refresh_export_report(folder)
    except (OSError, ValueError) as exc:  # the print files are complete; say why the page is missing
        done.notes.append(f"report.html not written: {exc}")
    return done


def verify_design(
    design_dir: str | Path,
    *,
    printer: str = DEFAULT_PRINTER,
    cup_diameter_mm: float | None = None,
    record_times: bool = True,
    progress: Any = None,
) -> Any:
    """Quick-verify a design folder through a trial export; results in ``design_dir/verify/``.

    The design is exported (OBJ, or the first format verify renders that ``printer`` takes, with a :data:`QUICK_TEXTURE_PX`
    atlas) to a temporary folder, that print is verified as :func:`finish_print` does, the pictures and
    ``verify.json`` (with the printer named) go into the design folder's
    ``verify/`` (replaced as a whole) and its ``report.html`` is rewritten
    with them. Returns the :class:`~saucerfab.verify.VerifyResult`.

    Raises:
        SaucerfabError: the trial export or the verify cannot be made.
    """
    from saucerfab.fabricate.options import FabOptions
    from saucerfab.fabricate.pipeline import export_design
    from saucerfab.fileio import atomic_dir
    from saucerfab.report_page import write_design_report
    from saucerfab.verify import verify_print

    from saucerfab.errors import ExportError
    from saucerfab.formats import WRITERS
    from saucerfab.profiles import load_profile
    from saucerfab.verify.printfolder import RENDERED_FORMATS

    design_dir = Path(design_dir)
    profile = load_profile(printer)
    # the trial print in a format verify renders and the printer takes (OBJ first: the quickest to read)
    rendered = [f for f in RENDERED_FORMATS if f in WRITERS]  # ("zip" is how verify reads a zipped OBJ)
    fmt = next((f for f in rendered if f in profile.accepted_formats), None)
    if fmt is None:
        raise ExportError(f"{profile.name} takes none of {', '.join(rendered)}, the formats verify renders")
    with tempfile.TemporaryDirectory(prefix="saucerfab-trial-") as tmp:
        trial = export_design(design_dir, Path(tmp) / "print", printer=profile, cup_diameter_mm=cup_diameter_mm,
                              formats=[fmt], options=FabOptions(texture_px=QUICK_TEXTURE_PX))
        with atomic_dir(design_dir / "verify") as vtmp:
            res = verify_print(trial.out, res=QUICK_RES, spp=QUICK_SPP, pictures_dir=vtmp, all_formats=False,
                               progress=progress)
            doc = res.to_dict(record_times=record_times)
            doc["folder"] = "(a trial export of this design)"
            doc["printer"] = trial.printer
            doc["cup_diameter_mm"] = trial.cup_diameter_mm
            doc["texture_px"] = QUICK_TEXTURE_PX
            (vtmp / "verify.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    write_design_report(design_dir)
    return res
