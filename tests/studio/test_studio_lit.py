"""An export seen under the room light in the studio (``POST .../exports/{printer}/lit``, saucerfab/studio/lit.py).

The run and its export are made with the library (``lit_run.py``: a flat
saucer painted with the heart, exported for the bureau as OBJ, about a
second) rather than by a design and an export job, so the one real worker
these tests start is the lit verify's. Nothing of the lit verify appears
until someone asks for it.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import pytest
from lit_run import PRINTER, done_run_with_export
from starlette.testclient import TestClient
from studio_helpers import TOKEN, signed_in

from saucerfab.studio.app import create_app
from saucerfab.studio.auth import Auth
from saucerfab.studio.jobs import Job, job_entry
from saucerfab.studio.results import LIT_DIR
from saucerfab.studio.workspace import Workspace


@pytest.fixture
def app(tmp_path: Path):  # type: ignore[no-untyped-def]
    return create_app(tmp_path / "ws", auth=Auth.shared(TOKEN), grace_s=15)


def _wait_lit(client: TestClient, rid: str, timeout_s: float = 60) -> tuple[dict[str, Any], set[float]]:
    """Poll the export until its lit verify is done or failed; returns it and the progress fractions seen."""
    seen: set[float] = set()
    deadline = time.monotonic() + timeout_s
    while True:
        ex = client.get(f"/api/runs/{rid}/exports/{PRINTER}").json()
        lit = ex.get("lit") or {}
        if lit.get("progress"):
            seen.add(lit["progress"]["fraction"])
        if lit.get("status") in ("done", "failed") or time.monotonic() > deadline:
            return ex, seen
        time.sleep(0.1)


def test_an_export_under_the_room_light_shows_each_lit_view_beside_the_emitted_one(app) -> None:  # type: ignore[no-untyped-def]
    ws = app.state.workspace
    rid = done_run_with_export(ws)
    folder = ws.runs / rid / "exports" / PRINTER
    before = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*"))
    with signed_in(app) as client:
        plain = client.get(f"/api/runs/{rid}/exports/{PRINTER}").json()
        assert plain["status"] == "done" and "lit" not in plain  # nobody asked: nothing more, nothing rendered
        r = client.post(f"/api/runs/{rid}/exports/{PRINTER}/lit")
        assert r.status_code == 202, r.text
        assert r.json()["lit"]["status"] in ("queued", "running") and r.json()["lit"]["light"] == "room"
        ex, fractions = _wait_lit(client, rid)
        lit = ex["lit"]
        assert lit["status"] == "done", lit
        assert lit["error"] is None and lit["progress"] is None and lit["finished"]
        assert lit["light"] == "room" and lit["cup_metal"] and lit["res"] == 128 and lit["spp"] == 16
        views = {(v["view"], v["eye"]): v for v in lit["views"]}
        assert set(views) == {("direct", "design"), ("reflected", "design")}
        for v in views.values():
            for k in ("lit_psnr_db", "flat_print_lit_psnr_db", "shading_pattern_db", "flat_pattern_db", "emitted_psnr_db",
                      "white_level"):
                assert isinstance(v[k], (int, float)) and math.isfinite(v[k]), (k, v)
            assert 0 < v["shading_p5"] <= v["shading_p95"] and 0 < v["flat_p5"] <= v["flat_p95"]
            for key, name in (("lit_picture_url", f"design_{v['view']}_lit.png"),
                              ("emitted_picture_url", f"design_{v['view']}.png")):
                assert v[key] == f"/api/runs/{rid}/files/exports/{PRINTER}/{LIT_DIR}/{name}", v
                pic = client.get(v[key])
                assert pic.status_code == 200 and pic.content[:8] == b"\x89PNG\r\n\x1a\n"
        # the heart is painted for the direct view: it reads under the lamp as in emitted colour
        assert views[("direct", "design")]["lit_psnr_db"] > 20
        # the record of the run carries the lit verify's state (the page polls it while it works)
        rec = client.get(f"/api/runs/{rid}").json()
        assert rec["exports"][PRINTER]["lit"]["status"] == "done"
        assert all(0 <= f <= 1 for f in fractions)
        # asked again once done: rendered again (the page offers it only when there is none or it failed)
        assert client.post(f"/api/runs/{rid}/exports/{PRINTER}/lit").status_code == 202
        again = _wait_lit(client, rid)[0]["lit"]
        assert again["status"] == "done", again
    # the export's own files are as they were; the lit verify is in its own folder beside them
    after = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_relative_to(folder / LIT_DIR)
                   and p != folder / LIT_DIR)
    assert after == before
    assert (folder / LIT_DIR / "verify.json").is_file()
    assert "Traceback" not in (ws.runs / rid / "worker.log").read_text()


def test_the_room_light_is_refused_until_the_export_is_done_and_once_at_a_time(app) -> None:  # type: ignore[no-untyped-def]
    ws = app.state.workspace
    rid = ws.create_run({}, "t")["id"]
    client = signed_in(app)  # no lifespan: queued jobs stay queued
    lit = f"/api/runs/{rid}/exports/{PRINTER}/lit"
    r = client.post(lit)
    assert r.status_code == 404 and "export it first" in r.json()["error"]
    assert client.post(f"/api/runs/20260101-000000-beef/exports/{PRINTER}/lit").status_code == 404

    def exporting(rec: dict[str, Any]) -> None:
        rec.update(status="done")
        rec["exports"][PRINTER] = {"status": "running", "error": None, "formats": None, "files": []}

    ws.update_run(rid, exporting)
    r = client.post(lit)
    assert r.status_code == 409 and "once it is done" in r.json()["error"]

    def exported(rec: dict[str, Any]) -> None:
        rec["exports"][PRINTER]["status"] = "done"

    ws.update_run(rid, exported)
    r = client.post(lit)
    assert r.status_code == 202 and r.json()["lit"]["status"] == "queued"
    assert app.state.queue.queued() == [Job("lit", rid, PRINTER)]
    r = client.post(lit)
    assert r.status_code == 409 and "already" in r.json()["error"]
    # while it is queued, no export replaces the folder it reads and the run is not deleted
    r = client.post(f"/api/runs/{rid}/exports", json={"printer": PRINTER})
    assert r.status_code == 409 and "room light" in r.json()["error"]
    r = client.delete(f"/api/runs/{rid}")
    assert r.status_code == 409 and "room light" in r.json()["error"]


def test_a_restart_fails_a_running_lit_verify_and_starts_a_waiting_one(tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "ws")
    a, b = ws.create_run({}, "a")["id"], ws.create_run({}, "b")["id"]
    for rid, status in ((a, "running"), (b, "queued")):
        def change(rec: dict[str, Any], status: str = status) -> None:
            rec.update(status="done")
            rec["exports"]["j55"] = {"status": "done", "lit": {"status": status, "progress": {"fraction": 0.5}}}

        ws.update_run(rid, change)
    assert ws.startup_scan() == ([], [])
    assert ws.queued_lits() == [(b, "j55")]
    lit = ws.read_run(a)["exports"]["j55"]["lit"]
    assert lit["status"] == "failed" and "ask for it again" in lit["error"] and lit["progress"] is None
    # the queue finds the lit entry of a lit job, the export's entry of an export job
    rec = ws.read_run(b)
    assert job_entry(rec, Job("lit", b, "j55")) is rec["exports"]["j55"]["lit"]
    assert job_entry(rec, Job("export", b, "j55")) is rec["exports"]["j55"]
    assert job_entry(rec, Job("lit", b, "ultimaker")) is None
    # a studio started on the workspace runs the waiting one (here on an export whose folder is gone: it fails,
    # saying so, and makes no folder)
    app = create_app(tmp_path / "ws", auth=Auth.shared(TOKEN), grace_s=15)
    with signed_in(app) as client:
        deadline = time.monotonic() + 60
        while (lit := client.get(f"/api/runs/{b}").json()["exports"]["j55"]["lit"])["status"] == "queued":
            assert time.monotonic() < deadline, lit
            time.sleep(0.1)
        while lit["status"] == "running" and time.monotonic() < deadline:
            time.sleep(0.1)
            lit = client.get(f"/api/runs/{b}").json()["exports"]["j55"]["lit"]
    assert lit["status"] == "failed" and "export it again" in lit["error"] and str(tmp_path) not in lit["error"], lit
    assert not (ws.runs / b / "exports").exists()
