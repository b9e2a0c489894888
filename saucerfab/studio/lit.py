"""An export seen under the room light: the studio's ``lit`` job (issue 45).

``POST /api/runs/{id}/exports/{printer}/lit`` asks for it (:func:`queue_lit`);
a worker process then runs :func:`lit_job`: ``saucerfab verify PRINT --light
room --eyes design`` as a library call on the export's own folder, at the
quick verify's size (:data:`~saucerfab.workflow.quick_verify.QUICK_RES`) and
verify's own samples a pixel (:data:`~saucerfab.verify.DEFAULT_SPP`, not the
quick verify's 4: at 4 the path-traced pictures are speckled and the scores
bound by their noise; on the demo's J55 export a flat plate's shading pattern
read 35.6 dB at 4 and 99 dB at 16), into ``exports/<printer>/verify_room/``
(:data:`~saucerfab.studio.results.LIT_DIR`, replaced as a whole). The
export's own ``verify/``, its zip and its report stay as they were: nobody
pays for the lit renders who does not ask.

Why an action on a finished export rather than an option of the export
request: the lit renders cost about as much again as the emitted verify, a
designer decides to look after seeing the export, and the export's folder is
kept (the design's quick verify renders a trial export that is gone once
verified, so lighting it would mean exporting again).

Its record is the export entry's ``lit``::

    {"status": "queued|running|done|failed", "error": null, "light": "room",
     "created", "started", "finished",
     "progress": {"fraction": 0..1, "message": "..."} while it runs, else null}

A new export for the printer replaces the folder and the entry, and with them
the lit verify (it belonged to the files that were replaced).
"""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from saucerfab.studio.results import LIT_DIR
from saucerfab.studio.workspace import Conflict, NotFound, Workspace, now_iso

#: the light the studio shows an export under (verify's ``--light``)
LIT_LIGHT = "room"
#: the eyes the lit verify renders (verify's ``--eyes``): the design eye, whose views verify lights by
#: default; the export's own verify has the other eyes' emitted views
LIT_EYES = "design"
#: the statuses of a lit verify that is not finished
LIT_ACTIVE = ("queued", "running")
#: the most run.json writes of the lit verify's progress a second (the page polls the run while it works)
PROGRESS_WRITES_PER_S = 2.0


def lit_entry(rec: dict[str, Any], printer: str) -> dict[str, Any] | None:
    """The ``lit`` record of ``rec``'s export for ``printer``, None when none was asked for."""
    ex = rec.get("exports", {}).get(printer)
    lit = ex.get("lit") if isinstance(ex, dict) else None
    return lit if isinstance(lit, dict) else None


def queue_lit(ws: Workspace, run_id: str, printer: str) -> dict[str, Any]:
    """Mark the lit verify of run ``run_id``'s export for ``printer`` queued; returns the run's record.

    Raises:
        NotFound: the run has no export for ``printer`` (404).
        Conflict: the export is not done, or its lit verify is queued or running already (409).
    """

    def change(rec: dict[str, Any]) -> None:
        ex = rec.get("exports", {}).get(printer)
        if not isinstance(ex, dict):
            raise NotFound(f"run {run_id} has no export for {printer[:40]!r}; export it first (POST .../exports)")
        if ex.get("status") != "done":
            raise Conflict(f"the export for {printer} is {ex.get('status')}; it can be seen under the room light "
                           "once it is done")
        old = lit_entry(rec, printer) or {}
        if old.get("status") in LIT_ACTIVE:
            raise Conflict(f"the export for {printer} is being rendered under the room light already; wait until "
                           "it is done")
        ex["lit"] = {"status": "queued", "error": None, "light": LIT_LIGHT, "created": now_iso(), "started": None,
                     "finished": None, "progress": None}

    return ws.update_run(run_id, change)


def _set_lit(ws: Workspace, run_id: str, printer: str, **fields: Any) -> None:
    """Update the lit record (when the export is still the one it was asked for: a new export drops it)."""

    def change(rec: dict[str, Any]) -> None:
        lit = lit_entry(rec, printer)
        if lit is not None:
            lit.update(fields)

    ws.update_run(run_id, change)


def lit_job(ws: Workspace, run_id: str, printer: str) -> None:
    """The worker's lit verify of ``exports/<printer>/`` into its ``verify_room/``; records how it ended.

    Errors are the record's ``error`` (a library error in its own words, a fault as a line naming
    ``worker.log``, where its traceback goes); the export itself is never touched.
    """
    from saucerfab.errors import SaucerfabError

    folder = ws.runs / run_id / "exports" / printer
    last = [0.0]

    def progress(message: str, fraction: float) -> None:
        now = time.perf_counter()
        if now - last[0] < 1.0 / PROGRESS_WRITES_PER_S and fraction < 1.0:
            return
        last[0] = now
        try:
            _set_lit(ws, run_id, printer, progress={"fraction": round(float(fraction), 3),
                                                    "message": ws.scrub(message)})
        except (OSError, NotFound) as exc:  # a full disk: the verify goes on; a deleted run: it ends below
            print(f"studio worker: lit progress not written: {exc}", file=sys.stderr)

    try:
        _render(folder, progress)
        _set_lit(ws, run_id, printer, status="done", error=None, finished=now_iso(), progress=None)
    except KeyboardInterrupt:
        _set_lit(ws, run_id, printer, status="failed", finished=now_iso(), progress=None,
                 error="the verify under the room light was stopped; ask for it again")
    except SaucerfabError as exc:
        _set_lit(ws, run_id, printer, status="failed", finished=now_iso(), progress=None, error=ws.scrub(str(exc)))
    except Exception as exc:  # noqa: BLE001 (a fault of saucerfab: said in the record, its traceback in worker.log)
        traceback.print_exc()
        _set_lit(ws, run_id, printer, status="failed", finished=now_iso(), progress=None,
                 error=f"internal error ({type(exc).__name__}); the traceback is in runs/{run_id}/worker.log")


def _render(folder: Path, progress: Callable[[str, float], None]) -> None:
    """``verify_print`` of the print ``folder`` under :data:`LIT_LIGHT`; pictures and verify.json in its
    :data:`~saucerfab.studio.results.LIT_DIR` (replaced whole, only once complete)."""
    from saucerfab.errors import InputFileError
    from saucerfab.fabricate.pipeline import export_lock
    from saucerfab.model.eyes import parse_eyes
    from saucerfab.verify import DEFAULT_SPP
    from saucerfab.verify.lighting import parse_light
    from saucerfab.workflow import quick_verify

    if not (folder / "export.json").is_file():  # checked first: the lock and the lit folder would make the folder
        raise InputFileError(f"the export for {folder.name} has no print files any more; export it again, then ask "
                             "for it under the room light")
    with export_lock(folder):  # no export replaces the folder meanwhile
        quick_verify(folder, folder / LIT_DIR, progress=progress, spp=DEFAULT_SPP, light=parse_light(LIT_LIGHT),
                     eyes=parse_eyes(LIT_EYES))
