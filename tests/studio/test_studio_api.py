"""The studio's HTTP API in-process (starlette.testclient): uploads, runs, events, cancel, resume, exports.

Every client signs in first (studio_helpers.signed_in: the token once in the
URL, then the session cookie), as the studio asks of everyone; signing in
itself and the users' isolation are test_studio_auth.py's. Tests that need
no worker use a TestClient outside its ``with`` block: the app's lifespan
(the job queue) does not start, so runs stay queued. The others start real
worker processes (spawn); each imports torch, so they are few and their
designs tiny (studio_helpers.TINY).
"""

from __future__ import annotations

import io
import json
import threading
import zipfile
from pathlib import Path

import numpy as np
import pytest
from starlette.testclient import TestClient
from studio_helpers import (
    AUTH,
    HEART,
    LONG,
    STAR,
    TINY,
    TOKEN,
    bomb_png,
    npy,
    pair,
    png,
    signed_in,
    sse_events,
    subject_png,
    upload,
    wait_in_stage,
    wait_status,
)

from saucerfab.studio.app import STATIC, create_app
from saucerfab.studio.auth import Auth


def studio_app(ws: Path, **kw):  # type: ignore[no-untyped-def]
    """The studio's app over ``ws`` with the tests' token (one shared user)."""
    return create_app(ws, auth=Auth.shared(TOKEN), **kw)


@pytest.fixture
def app(tmp_path: Path):  # type: ignore[no-untyped-def]
    return studio_app(tmp_path / "ws", grace_s=15)


@pytest.fixture
def idle(app) -> TestClient:  # type: ignore[no-untyped-def]
    """A signed-in client with no job queue running (no lifespan): runs stay queued."""
    return signed_in(app)


# --------------------------------------------------------------------------- no workers


def test_page_options_and_unknown_routes(idle: TestClient) -> None:
    r = idle.get("/api/options")
    assert r.status_code == 200
    doc = r.json()
    assert "waves" in doc["shapes"] and {"key": "j55", "name": "Stratasys J55 Prime"} in doc["printers"]
    assert doc["defaults"]["max_iters"] is None and doc["defaults"]["resolution"] == 150  # None: the method's cap
    # each method's cap: (pictures with a subject, photographs)
    assert doc["stage_caps"] == {"auto": [120, 90], "fast": [120, 120], "paper": [400, 400]}
    assert doc["defaults"]["method"] == "auto"
    assert set(doc["fit_rules"]) == set(doc["fits"]) == {"pad", "crop"}
    assert doc["limits"]["max_upload_bytes"] == 64 << 20
    names = {s["name"]: s for s in doc["samples"]}
    assert names["direct_heart"]["role"] == "direct"
    assert idle.get(names["direct_heart"]["url"]).content == HEART.read_bytes()
    if (STATIC / "index.html").is_file():  # the page is the other half of issue 20
        assert idle.get("/").status_code == 200
    r = idle.get("/api/nothing")
    assert r.status_code == 404 and "error" in r.json()


def test_options_carry_peoples_words_for_the_optimizer_keys(idle: TestClient) -> None:
    from saucerfab.pages.labels import api_labels

    labels = idle.get("/api/options").json()["labels"]
    assert labels == api_labels()  # the page reads the one table (saucerfab/pages/labels.py), never a copy
    assert labels["stages"]["bw_sigma_large"].startswith("Smooth shaping, coarse")
    assert "E_barrier" in labels["hidden_energies"] and labels["energies"]["E_visual"] == "image error"


def test_an_exports_check_summary_counts_the_findings(tmp_path: Path) -> None:
    from saucerfab.studio.results import checks_summary

    info = {"severity": "info", "code": "units", "message": "OBJ states no units", "where": None}
    error = {"severity": "error", "code": "not_watertight", "message": "12 open edges", "where": None}
    (tmp_path / "check.json").write_text(json.dumps({"schema": "saucerfab.check/1", "files": [
        {"path": "saucer.obj", "verdict": "printable", "findings": [info, info]},
        {"path": "saucer.3mf", "verdict": "not printable", "findings": [error]},
    ]}))
    obj, three_mf = checks_summary(tmp_path)
    assert obj["printable"] and obj["counts"] == {"error": 0, "warning": 0, "info": 2}
    assert obj["counts_text"] == "0 errors, 0 warnings, 2 info findings"  # as the print's report.html says it
    assert not three_mf["printable"] and three_mf["counts_text"] == "1 error, 0 warnings, 0 info findings"
    assert three_mf["findings"] == [{"code": "not_watertight", "severity": "error", "message": "12 open edges"}]


def test_bad_uploads_are_4xx_with_a_message(tmp_path: Path) -> None:
    client = signed_in(studio_app(tmp_path / "ws", max_upload_bytes=100_000))
    cases = [
        ("direct", b"plain text, not a picture", 400, "not a PNG, JPEG or WebP"),
        ("direct", bomb_png(), 400, "64,000,000 pixels"),
        ("reflected", png(np.zeros((16, 16, 4), np.uint8)), 400, "fully transparent"),
        ("shape", npy(np.zeros((3, 3, 3))), 400, "2-D"),
        ("shape", npy(np.zeros((1, 5))), 400, "2x2"),
        ("direct", b"", 400, "empty"),
        ("teapot", subject_png(0), 400, "role"),
        ("direct", b"\x89PNG\r\n\x1a\n" + bytes(200_000), 413, "100,000 bytes"),
    ]
    for role, data, status, words in cases:
        r = client.post(f"/api/uploads?role={role}&name=mine.png", content=data)
        assert r.status_code == status, (role, words, r.text)
        msg = r.json()["error"]
        assert words in msg and "Traceback" not in msg and str(tmp_path) not in msg, msg
    # a streamed body (no Content-Length) over the limit is cut off as it arrives
    r = client.post("/api/uploads?role=direct&name=big.png", content=iter([b"\x89PNG\r\n\x1a\n", bytes(150_000)]))
    assert r.status_code == 413
    ws = client.app.state.workspace  # type: ignore[attr-defined]
    assert [p.name for p in ws.uploads.iterdir()] == [".incoming"] and not list((ws.uploads / ".incoming").iterdir())


def test_twenty_uploads_in_a_row(idle: TestClient) -> None:
    ids = {upload(idle, subject_png(i), "direct", f"p{i}.png")["id"] for i in range(20)}
    assert len(ids) == 20
    assert idle.get("/api/options").status_code == 200
    for i in list(ids)[:3]:
        r = idle.get(f"/api/uploads/{i}/thumb.png")
        assert r.status_code == 200 and r.headers["content-type"] == "image/png"


def test_fitted_picture(idle: TestClient) -> None:
    wide = np.full((20, 60, 3), 255, np.uint8)
    wide[:, 20:40] = (200, 0, 0)
    rec = upload(idle, png(wide), "direct", "wide.png")
    from PIL import Image

    r = idle.get(f"/api/uploads/{rec['id']}/fitted.png?fit=pad&background=%23000000&size=60")
    im = np.asarray(Image.open(io.BytesIO(r.content)))
    assert im.shape == (60, 60, 3) and im[0, 0].tolist() == [0, 0, 0]  # padded with the background asked for
    r = idle.get(f"/api/uploads/{rec['id']}/fitted.png?fit=crop&size=60")
    crop = np.asarray(Image.open(io.BytesIO(r.content))).astype(int)
    # the middle fills the frame
    assert crop[30, 30].tolist() == [200, 0, 0] and crop[..., 0].mean() - crop[..., 1].mean() > 150
    assert idle.get(f"/api/uploads/{rec['id']}/fitted.png?fit=stretch").status_code == 400
    assert idle.get(f"/api/uploads/{rec['id']}/fitted.png?size=99999").status_code == 400
    assert idle.get(f"/api/uploads/{rec['id']}/fitted.png?background=blue").status_code == 400
    assert idle.get("/api/uploads/0123456789abcdef/fitted.png").status_code == 404


def test_run_options_are_checked_at_once(idle: TestClient) -> None:
    ids = pair(idle)
    black = upload(idle, png(np.zeros((32, 32, 3), np.uint8)), "direct_mask", "black.png")["id"]
    bad = [
        ({"direct": ids["direct"]}, "reflected"),
        ({**ids, "colour": "red"}, "unknown option 'colour'"),
        ({**ids, "max_iters": "many"}, "whole number"),
        ({**ids, "max_iters": 0}, "at least 1"),
        ({**ids, "printer": "../../etc/passwd.toml"}, "unknown printer"),
        ({**ids, "scene": "/etc/scene.toml"}, "unknown scene"),
        ({**ids, "shape": "/etc/passwd"}, "unknown base shape"),
        ({**ids, "shape": ids["direct"]}, "not a shape"),
        ({**ids, "fit": "stretch"}, "--fit"),
        ({**ids, "enhancement": "subject", "direct_mask": black}, "no foreground"),
        ([1, 2], "JSON object"),
    ]
    for body, words in bad:
        r = idle.post("/api/runs", json=body)
        assert r.status_code == 400 and words in r.json()["error"], (body, r.text)
    assert idle.post("/api/runs", json={**ids, "reflected": "0123456789abcdef"}).status_code == 404
    r = idle.post("/api/runs", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 400 and "JSON" in r.json()["error"]
    assert idle.get("/api/runs").json() == []  # nothing was made of the refusals
    tall = upload(idle, npy(np.full((8, 8), 1e6)), "shape", "mm.npy")["id"]  # a heightfield in micrometres
    r = idle.post("/api/runs", json={**ids, "shape": tall})
    assert r.status_code == 400 and "height_scale" in r.json()["error"]


def test_paths_from_the_client_are_never_trusted(idle: TestClient) -> None:
    run = idle.post("/api/runs", json={**pair(idle), **TINY}).json()
    rid = run["id"]
    d = idle.app.state.workspace.runs / rid  # type: ignore[attr-defined]
    (d / "secret.txt").write_text("no")
    assert idle.get(f"/api/runs/{rid}/files/run.json").json()["id"] == rid
    for url in [
        "/api/runs/../../etc/passwd", f"/api/runs/{rid}/files/../run.json", f"/api/runs/{rid}/files/%2e%2e/run.json",
        f"/api/runs/{rid}/files/%2e%2e/%2e%2e/studio.json", f"/api/runs/{rid}/files/%2Fetc%2Fpasswd",
        f"/api/runs/{rid}/files//etc/passwd", f"/api/runs/{rid}/files/secret.txt", f"/api/runs/{rid}/files/.lock",
        f"/api/runs/{rid}/files/design/../../../studio.json", "/api/runs/..%2F..%2Fetc/files/passwd",
        "/api/runs/20261202-071500-zzzz", "/api/uploads/..%2F..%2Fstudio.json/thumb.png",
        f"/api/runs/{rid}/exports/..%2F..%2Fstudio.json", "/static/..%2F..%2F__init__.py",
    ]:
        r = idle.get(url)
        assert r.status_code == 404, (url, r.status_code, r.text[:200])
    (d / "link.json").symlink_to(idle.app.state.workspace.root / "studio.json")  # type: ignore[attr-defined]
    assert idle.get(f"/api/runs/{rid}/files/link.json").status_code == 404


def test_cancel_queued_duplicate_delete(idle: TestClient) -> None:
    ids = pair(idle)
    run = idle.post("/api/runs", json={**ids, **TINY, "title": "first"}).json()
    rid = run["id"]
    assert run["status"] == "queued" and run["title"] == "first" and run["options"]["direct"] == ids["direct"]
    assert idle.delete(f"/api/runs/{rid}").status_code == 409  # queued: cancel first
    assert idle.post(f"/api/runs/{rid}/resume").status_code == 409
    r = idle.post(f"/api/runs/{rid}/cancel")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    assert idle.post(f"/api/runs/{rid}/cancel").status_code == 409
    dup = idle.post(f"/api/runs/{rid}/duplicate", json={"shape": "bowl", "max_iters": None})
    assert dup.status_code == 201, dup.text
    d = dup.json()
    assert d["id"] != rid and d["title"] == "first (copy)" and d["options"]["shape"] == "bowl"
    assert "max_iters" not in d["options"] and d["options"]["direct"] == ids["direct"]
    assert idle.post(f"/api/runs/{rid}/duplicate", json={"shape": "nope"}).status_code == 400
    assert [x["id"] for x in idle.get("/api/runs").json()] == [d["id"], rid]
    listed = idle.get("/api/runs").json()[1]
    assert set(listed) == {"id", "title", "status", "created", "thumb_url", "error", "owner"}  # owner: the admin's list
    assert idle.get(listed["thumb_url"]).status_code == 200
    assert idle.delete(f"/api/runs/{rid}").status_code == 200
    assert idle.get(f"/api/runs/{rid}").status_code == 404
    assert idle.post(f"/api/runs/{rid}/exports", json={"printer": "j55"}).status_code == 404
    assert idle.post(f"/api/runs/{d['id']}/exports", json={"printer": "j55"}).status_code == 409  # not designed


def test_event_stream_of_a_run_deleted_meanwhile(idle: TestClient) -> None:
    rid = idle.post("/api/runs", json={**pair(idle), **TINY}).json()["id"]
    ws = idle.app.state.workspace  # type: ignore[attr-defined]
    (ws.runs / rid / "progress.json").write_text(json.dumps({"stage": "x", "iteration": 3}))

    def later() -> None:
        import time

        time.sleep(0.6)
        import os

        os.replace(ws.runs / rid, ws.runs / ".deleted-by-the-test")  # as delete_run does, in one step

    t = threading.Thread(target=later)
    t.start()
    with idle.stream("GET", f"/api/runs/{rid}/events") as s:
        assert s.headers["content-type"].startswith("text/event-stream")
        events = list(sse_events(s.iter_lines()))
    t.join()
    assert events[0] == ("status", events[0][1]) and events[0][1]["status"] == "queued"
    assert ("progress", {"stage": "x", "iteration": 3}) in events
    assert events[-1][1]["status"] == "deleted"
    assert idle.get(f"/api/runs/{rid}/events").status_code == 404


def test_internal_error_is_a_500_without_traceback(tmp_path: Path) -> None:
    app = studio_app(tmp_path / "ws")
    client = signed_in(app, raise_server_exceptions=False)
    app.state.workspace.list_runs = lambda: 1 / 0  # a fault of the server itself
    r = client.get("/api/runs")
    assert r.status_code == 500 and r.json()["error"].startswith("internal error")
    assert "Traceback" not in r.text and "ZeroDivision" in r.text


# --------------------------------------------------------------------------- real workers


def test_design_verify_export_download(app) -> None:  # type: ignore[no-untyped-def]
    """Start -> events -> done with results, the 3D viewer, an export with its findings, the zip."""
    with signed_in(app) as client:
        run = client.post("/api/runs", json={**pair(client), **TINY, "verify": True}).json()
        rid = run["id"]
        with client.stream("GET", f"/api/runs/{rid}/events") as s:
            events = list(sse_events(s.iter_lines()))
        kinds = [k for k, _ in events]
        assert kinds[0] == "status" and "progress" in kinds and events[-1][1]["status"] == "done", events[-1]
        looks = [d["looks"] for k, d in events if k == "progress" and d.get("looks")]
        assert looks and looks[0]["stage"] == "first_look"
        assert client.get(f"/api/runs/{rid}/files/{looks[0]['files']['composite']}").status_code == 200
        assert any(d.get("phase") == "verify" for k, d in events if k == "progress")
        done = client.get(f"/api/runs/{rid}").json()
        res = done["results"]
        assert set(res["images"]) >= {"composite", "direct", "reflected", "height_change"}
        for url in [*res["images"].values(), res["report_url"]]:
            assert client.get(url).status_code == 200, url
        assert res["verify"] and {"view", "eye", "psnr_db", "coverage", "passed"} <= set(res["verify"][0])
        whole = [r for r in res["verify"] if r["view"] == "whole"]  # the whole view from each eye (verify/3)
        assert [r["eye"] for r in whole] == ["design", "left", "right"] and len(whole[0]["stray"]) == 2
        assert client.get(whole[0]["picture_url"]).status_code == 200
        assert client.get(res["verify"][0]["picture_url"]).status_code == 200
        page = client.get(res["viewer_url"])
        assert page.status_code == 200 and "importmap" in page.text and "saucer-viewer" in page.text
        assert "<h1" not in page.text  # a bare page for the iframe, not a report
        # the run is an ordinary design folder: the CLI's export reads it
        design = app.state.workspace.runs / rid / "design"
        assert json.loads((design / "design.json").read_text())["schema"] == "saucerfab.design/1"

        assert client.post(f"/api/runs/{rid}/exports", json={"printer": "nope"}).status_code == 400
        assert client.post(f"/api/runs/{rid}/exports", json={"printer": "j55", "formats": ["doc"]}).status_code == 400
        r = client.post(f"/api/runs/{rid}/exports", json={"printer": "j55", "formats": ["3mf"]})
        assert r.status_code == 202 and r.json()["status"] == "queued"
        ex = _wait_export(client, rid, "j55")
        assert ex["status"] == "done", ex
        assert ex["printable"] is True and ex["check"][0]["file"] == "saucer.3mf"
        assert {"code", "severity", "message"} <= set(ex["check"][0]["findings"][0])
        assert ex["verify"] and client.get(ex["report_url"]).status_code == 200
        z = client.get(ex["zip_url"])
        assert z.status_code == 200 and "attachment" in z.headers["content-disposition"]
        names = zipfile.ZipFile(io.BytesIO(z.content)).namelist()
        assert "j55/saucer.3mf" in names and "j55/check.json" in names and "j55/report.html" in names
        assert client.get(f"/api/runs/{rid}/exports/bureau").status_code == 404


def _wait_export(client: TestClient, rid: str, printer: str, timeout_s: float = 120) -> dict:
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        ex = client.get(f"/api/runs/{rid}/exports/{printer}").json()
        if ex["status"] in ("done", "failed") or time.monotonic() > deadline:
            return ex
        time.sleep(0.2)


def test_cancel_then_resume_from_the_checkpoint(app) -> None:  # type: ignore[no-untyped-def]
    with signed_in(app) as client:
        rid = client.post("/api/runs", json={**pair(client), **LONG}).json()["id"]
        wait_in_stage(client, rid)
        r = client.post(f"/api/runs/{rid}/cancel")
        assert r.status_code == 200 and r.json()["status"] in ("cancelling", "cancelled")
        run = wait_status(client, rid, ("cancelled", "failed", "done"))
        assert run["status"] == "cancelled", run
        assert (app.state.workspace.runs / rid / ".design.checkpoint" / "state.npz").is_file()
        r = client.post(f"/api/runs/{rid}/resume")
        assert r.status_code == 200 and r.json()["status"] == "queued"
        run = wait_status(client, rid, ("done", "failed", "cancelled"))
        assert run["status"] == "done", run
        log = (app.state.workspace.runs / rid / "worker.log").read_text()
        assert "resuming from checkpoint" in log  # run_design went on from the checkpoint the cancel saved
        assert not (app.state.workspace.runs / rid / ".design.checkpoint").exists()


def test_two_tabs_at_once(tmp_path: Path) -> None:
    """Two clients upload and start designs at the same time (two workers at once): two intact design folders."""
    app = studio_app(tmp_path / "ws", jobs=2)
    with signed_in(app) as tab1:
        tab2 = signed_in(app)  # the same server (one job queue), another connection
        made: dict[str, tuple[str, dict]] = {}

        def work(tab: TestClient, name: str, seed: int) -> None:
            ids = {"direct": upload(tab, subject_png(seed), "direct", f"{name}-a.png")["id"],
                   "reflected": upload(tab, subject_png(seed + 1), "reflected", f"{name}-b.png")["id"]}
            r = tab.post("/api/runs", json={**ids, **TINY})
            assert r.status_code == 201, r.text
            made[name] = (r.json()["id"], ids)

        threads = [threading.Thread(target=work, args=(t, n, s)) for t, n, s in ((tab1, "one", 10), (tab2, "two", 20))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert len(made) == 2
        ws = app.state.workspace
        for name, (rid, ids) in made.items():
            assert wait_status(tab1, rid, ("done", "failed"))["status"] == "done"
            inputs = json.loads((ws.runs / rid / "design" / "design.json").read_text())["inputs"]
            assert inputs["direct"]["file"] == f"{name}-a.png" and inputs["reflected"]["file"] == f"{name}-b.png"
            assert inputs["direct"]["sha256"].startswith(ids["direct"])


def test_restart_with_a_design_half_done(tmp_path: Path) -> None:
    """The server dies while a design runs; a new server shows it interrupted; resumed, it finishes."""
    import os
    import signal

    ws_dir = tmp_path / "ws"
    app = studio_app(ws_dir)
    with signed_in(app) as client:
        rid = client.post("/api/runs", json={**pair(client), **LONG}).json()["id"]
        wait_in_stage(client, rid)
        pid = app.state.queue.running()[rid]
        app.state.queue.abandon()  # the server is gone, as in a crash ...
        os.kill(pid, signal.SIGKILL)  # ... and its worker with it
    assert json.loads((ws_dir / "runs" / rid / "run.json").read_text())["status"] == "running"
    again = studio_app(ws_dir)
    with signed_in(again) as client:
        run = client.get(f"/api/runs/{rid}").json()
        assert run["status"] == "interrupted" and "resume" in run["error"]
        assert client.post(f"/api/runs/{rid}/resume").status_code == 200
        assert wait_status(client, rid, ("done", "failed"))["status"] == "done"


def test_client_leaving_the_event_stream_mid_run(tmp_path: Path) -> None:
    """Under uvicorn: a client reads one event and disconnects; the run still finishes and the server answers."""
    import httpx2 as httpx  # starlette.testclient's client (the dev extra); a real HTTP client here
    import uvicorn

    app = studio_app(tmp_path / "ws")
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="on"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    import time

    while not server.started:
        time.sleep(0.05)
    port = server.servers[0].sockets[0].getsockname()[1]
    base = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=base, timeout=30, headers=AUTH) as client:  # a script signs in with the header
            ids = {"direct": upload(client, HEART.read_bytes(), "direct", "h.png")["id"],
                   "reflected": upload(client, STAR.read_bytes(), "reflected", "s.png")["id"]}
            rid = client.post("/api/runs", json={**ids, **TINY}).json()["id"]
            with client.stream("GET", f"/api/runs/{rid}/events") as s:
                assert s.headers["content-type"].startswith("text/event-stream")
                kind, _ = next(sse_events(s.iter_lines()))
                assert kind == "status"
            # gone mid-run; the run goes on
            assert wait_status(client, rid, ("done", "failed"))["status"] == "done"
            with client.stream("GET", f"/api/runs/{rid}/events") as s:  # a finished run's stream ends at once
                assert [k for k, _ in sse_events(s.iter_lines())][-1] == "status"
        # raw paths as a hostile client sends them (httpx would tidy the dot segments away first)
        import http.client

        for raw in (f"/api/runs/{rid}/files/../run.json", f"/api/runs/{rid}/files/design/../../../studio.json",
                    "/api/runs/../../etc/passwd", "/static/../studio/app.py"):
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
            conn.request("GET", raw, headers=AUTH)
            resp = conn.getresponse()
            assert resp.status == 404 and b"schema" not in resp.read(), raw
            conn.close()
    finally:
        server.should_exit = True
        thread.join(timeout=30)
    assert not thread.is_alive()
