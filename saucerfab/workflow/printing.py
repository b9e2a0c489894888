"""A design folder -> a finished print folder: export, check every file, quick verify, report.

:func:`make_print` is the sequence every front door runs (``saucerfab
export``, ``saucerfab batch``, the studio's export); :func:`finish_print` is
its part after the export:

1. ``check``: every mesh file (an OBJ zip is checked as what a bureau
   unpacks, :mod:`saucerfab.workflow.checks`), results in ``check.json``
   (schema ``saucerfab.check/1``, no times, so the folder is reproducible);
2. ``verify``: a quick ray trace of the first textured file from the design
   eye and a viewer's two eyes (:mod:`saucerfab.workflow.quick_verify`),
   pictures and ``verify.json`` in ``verify/``;
3. ``report.html`` (:mod:`saucerfab.pages.folder_pages`).

Each file is written atomically; a failure of step 2 or 3 never removes the
print files, and is reported as a note rather than raised, because the
print itself is complete and printable at that point.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from saucerfab.workflow.checks import CheckedFile, check_export, check_json
from saucerfab.workflow.quick_verify import Progress, quick_verify

if TYPE_CHECKING:
    from saucerfab.model.design import Design

#: the stages of :func:`make_print`, in order (``on_stage`` is told each as it starts)
STAGES = ("export", "check", "verify", "report")

#: ``on_stage(name)``: a stage of :data:`STAGES` starts
OnStage = Callable[[str], None]


@dataclass
class PrintResult:
    """What :func:`make_print` (or :func:`finish_print`) made.

    Attributes:
        export: the :class:`~saucerfab.fabricate.pipeline.ExportResult` (its folder, files and sizes).
        checks: each checked mesh file (its report None when the checker is absent); empty when not checked.
        verify: the :class:`~saucerfab.verify.VerifyResult`, or None when skipped or failed.
        notes: what could not be done and why (verify or report failures).
    """

    export: Any = None
    checks: list[CheckedFile] = field(default_factory=list)
    verify: Any = None
    notes: list[str] = field(default_factory=list)

    @property
    def check_exit_code(self) -> int:
        """The worst check's exit code (0 printable, 1 not printable, 2 unreadable); 0 when nothing was checked."""
        return max([int(c.report.exit_code) for c in self.checks if c.report is not None], default=0)


def _tell(on_stage: OnStage | None, name: str) -> None:
    if on_stage is not None:
        on_stage(name)


def finish_print(
    result: Any,
    profile: Any,
    *,
    check: bool = True,
    verify: bool = True,
    record_times: bool = True,
    progress: Progress | None = None,
    write_check_json: bool = True,
    scratch: Path | None = None,
    on_stage: OnStage | None = None,
) -> PrintResult:
    """Check, verify and report an export folder (see the module docstring).

    Args:
        result: the :class:`~saucerfab.fabricate.pipeline.ExportResult`.
        profile: the printer profile (or its key) it was exported for.
        check, verify: run those steps.
        record_times: keep wall times (seconds) in ``verify.json`` (batch turns them off).
        progress: ``progress(message, fraction)`` for the verify renders.
        write_check_json: write ``check.json`` into the folder (the batch keeps each file's
            check in its job folder instead).
        scratch: where a zipped OBJ is unpacked for its check (default: the system's temp folder).
        on_stage: told each stage of :data:`STAGES` after the export as it starts.
    """
    from saucerfab.errors import SaucerfabError
    from saucerfab.files.fileio import write_text_atomic

    folder = Path(result.out)
    done = PrintResult(export=result)
    if check:
        _tell(on_stage, "check")
        done.checks = check_export(result, profile, scratch=scratch)
        if write_check_json:
            write_text_atomic(folder / "check.json", check_json(folder, done.checks))
    if verify:
        _tell(on_stage, "verify")
        try:
            done.verify = quick_verify(folder, folder / "verify", record_times=record_times, progress=progress)
        except (SaucerfabError, OSError) as exc:  # the print files are complete: say why, as a note
            done.notes.append(f"not verified: {exc}")
    _tell(on_stage, "report")
    try:
        from saucerfab.pages.folder_pages import refresh_export_report

        refresh_export_report(folder)
    except (SaucerfabError, OSError, ValueError) as exc:  # the print files are complete; say why the page is missing
        done.notes.append(f"report.html not written: {exc}")
    return done


def make_print(
    design: Design | str | Path,
    out: str | Path,
    *,
    printer: Any = None,
    cup_diameter_mm: float | None = None,
    formats: Sequence[str] | None = None,
    options: Any = None,
    allow_other_formats: bool = False,
    check: bool = True,
    verify: bool = True,
    record_times: bool = True,
    progress: Progress | None = None,
    verify_progress: Progress | None = None,
    write_check_json: bool = True,
    scratch: Path | None = None,
    on_stage: OnStage | None = None,
) -> PrintResult:
    """Export a design to ``out`` for a printer, then :func:`finish_print` it: the whole sequence.

    Args:
        design: the design (:func:`~saucerfab.workflow.run_design`'s) or its folder; what it was
            made for (:attr:`~saucerfab.model.design.Design.intent`) is the default of each option left None.
        out: the print folder to write (replaced whole).
        printer, cup_diameter_mm, formats, options, allow_other_formats: as
            :func:`~saucerfab.fabricate.pipeline.export_design` takes them (None: the design's printer and
            cup width in mm, the printer's preferred format, default :class:`~saucerfab.fabricate.options.FabOptions`).
        check, verify, record_times, write_check_json, scratch: as :func:`finish_print` takes them.
        progress: ``progress(step, fraction)`` for the export; ``verify_progress`` for the verify renders.
        on_stage: told each stage of :data:`STAGES` as it starts.

    Raises:
        SaucerfabError: the design cannot be read or exported (nothing of the print is left then).
    """
    # the module, not the function: tests replace pipeline.export_design to watch what is asked
    import saucerfab.fabricate.pipeline as pipeline

    _tell(on_stage, "export")
    result = pipeline.export_design(design, out, printer=printer, cup_diameter_mm=cup_diameter_mm,
                                    formats=list(formats) if formats is not None else None, options=options,
                                    progress=progress, allow_other_formats=allow_other_formats)
    return finish_print(result, result.profile, check=check, verify=verify, record_times=record_times,
                        progress=verify_progress, write_check_json=write_check_json, scratch=scratch,
                        on_stage=on_stage)
