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

import json
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: quick verify of every export: render size and samples per pixel
QUICK_RES = 128
QUICK_SPP = 4


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


def check_file(path: Path, profile: Any) -> Any | None:
    """``saucerfab.check.check_mesh(path, printer=profile)``, or None where the checker is absent.

    A zipped OBJ (``--zip-obj``) is checked as what the bureau unpacks: the
    archive (written by us a moment ago, so its names are safe) goes to a
    temporary folder and its ``.obj`` is checked with the MTL and PNG beside it.
    """
    try:
        from saucerfab.check import check_mesh
    except ImportError:
        return None
    if path.suffix != ".zip":
        return check_mesh(path, printer=profile)
    with tempfile.TemporaryDirectory(prefix="saucerfab-check-") as tmp, zipfile.ZipFile(path) as zf:
        zf.extractall(tmp)
        objs = sorted(Path(tmp).glob("*.obj"))
        if not objs:
            return check_mesh(path, printer=profile)
        return check_mesh(objs[0], printer=profile)


def mesh_files(result: Any) -> list[Path]:
    """The files of an :class:`~saucerfab.fabricate.pipeline.ExportResult` that hold a mesh."""
    from saucerfab.fabricate.registry import WRITERS

    out: list[Path] = []
    for fmt, paths in result.files.items():
        suffix = WRITERS[fmt].mesh_suffix
        out += [p for p in paths if p.suffix == suffix] or [p for p in paths if p.suffix == ".zip"]
    return out


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
        for path in mesh_files(result):
            done.checks.append((path, check_file(path, profile)))
        docs = []
        for path, rep in done.checks:
            if rep is None:
                continue
            d = rep.to_dict()
            d.pop("elapsed_s", None)  # the folder stays byte-identical run to run
            d["path"] = path.name
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
    printer: str = "j55",
    cup_diameter_mm: float | None = None,
    record_times: bool = True,
    progress: Any = None,
) -> Any:
    """Quick-verify a design folder through a trial export; results in ``design_dir/verify/``.

    The design is exported (OBJ, for ``printer``) to a temporary folder, that
    print is verified as :func:`finish_print` does, the pictures and
    ``verify.json`` (with the printer named) go into the design folder's
    ``verify/`` (replaced as a whole) and its ``report.html`` is rewritten
    with them. Returns the :class:`~saucerfab.verify.VerifyResult`.

    Raises:
        SaucerfabError: the trial export or the verify cannot be made.
    """
    from saucerfab.fabricate.pipeline import export_design
    from saucerfab.fileio import atomic_dir
    from saucerfab.report_page import write_design_report
    from saucerfab.verify import verify_print

    design_dir = Path(design_dir)
    with tempfile.TemporaryDirectory(prefix="saucerfab-trial-") as tmp:
        trial = export_design(design_dir, Path(tmp) / "print", printer=printer, cup_diameter_mm=cup_diameter_mm,
                              formats=["obj"])
        with atomic_dir(design_dir / "verify") as vtmp:
            res = verify_print(trial.out, res=QUICK_RES, spp=QUICK_SPP, pictures_dir=vtmp, all_formats=False,
                               progress=progress)
            doc = res.to_dict(record_times=record_times)
            doc["folder"] = "(a trial export of this design)"
            doc["printer"] = trial.printer
            doc["cup_diameter_mm"] = trial.cup_diameter_mm
            (vtmp / "verify.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    write_design_report(design_dir)
    return res
