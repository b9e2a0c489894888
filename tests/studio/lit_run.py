"""A done run with a done export, made with the library in this process (about a second), for the tests of an
export seen under the room light (``test_studio_lit.py``, ``test_browser_lit.py``).

The saucer is flat and painted with the heart from the design eye
(``tests/verify_designs.py``), exported as OBJ: the lit verify of it is the
one real job those tests run, so they need no design or export worker.
"""

from __future__ import annotations

from typing import Any

from saucerfab.studio.workspace import Workspace

#: the printer of the export (a flat saucer passes its wall rules; OBJ is the quickest to read)
PRINTER = "bureau"


def done_run_with_export(ws: Workspace, title: str = "heart / star") -> str:
    """A run marked done whose export for :data:`PRINTER` is done; returns its id (no design folder: the
    page shows its exports, not its results)."""
    from verify_designs import painted_design

    from saucerfab.fabricate.pipeline import export_design

    rid = ws.create_run({}, title)["id"]
    out = ws.runs / rid / "exports" / PRINTER
    export_design(painted_design(0.0, resolution=20), out, printer=PRINTER, formats=["obj"], cup_diameter_mm=80)
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())

    def done(rec: dict[str, Any]) -> None:
        rec.update(status="done", started=rec["created"], finished=rec["created"])
        rec["exports"][PRINTER] = {"status": "done", "error": None, "formats": ["obj"], "printable": True,
                                   "files": files, "zip": None, "created": rec["created"]}

    ws.update_run(rid, done)
    return rid
