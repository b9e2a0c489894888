"""The studio shared fairly (issue 39, part 2): round-robin between users, per-user limits, the queue position,
cancel isolation, a restart mid-queue, a full disk, and the jobs on a Dask cluster (``--scheduler``).

Most tests run in-process without the app's lifespan (no worker starts, runs
stay queued); the restart, the full-disk design and the cluster run real,
tiny designs. Users: ``alice`` and ``bob`` (each their own runs), ``admin``.
"""

from __future__ import annotations

import concurrent.futures
import errno
import json
import time
from pathlib import Path
from typing import Any

import pytest
from starlette.testclient import TestClient
from studio_helpers import HEART, LOCAL, LONG, STAR, TINY, signed_in, subject_png, upload, wait_in_stage, wait_status

from saucerfab.studio.app import create_app
from saucerfab.studio.auth import Auth
from saucerfab.studio.jobs import DEFAULT_MAX_QUEUED_PER_USER, Job, JobQueue
from saucerfab.studio.workspace import Workspace

ADMIN, ALICE, BOB = "admin-token-0123456789abcdef", "alice-token-0123456789abcdef", "bob-token-0123456789abcdef"
TEAM = {"admin": ADMIN, "alice": ALICE, "bob": BOB}
ENOSPC = OSError(errno.ENOSPC, "No space left on device")


def team_app(ws: Path, **kw: Any) -> Any:
    return create_app(ws, auth=Auth(TEAM, "--token-file team.txt"), **kw)


def pictures(client: TestClient) -> dict[str, str]:
    return {"direct": upload(client, HEART.read_bytes(), "direct", "heart.png")["id"],
            "reflected": upload(client, STAR.read_bytes(), "reflected", "star.png")["id"]}


def new_run(client: TestClient, pics: dict[str, str], **options: Any) -> Any:
    return client.post("/api/runs", json={**pics, **TINY, **options})


# --------------------------------------------------------------------------- the queue's order


def test_round_robin_between_users(tmp_path: Path) -> None:
    """Alice's ten queued runs do not hold back Bob's one: the users take turns, each their oldest job first."""
    q = JobQueue(Workspace(tmp_path))  # not started: nothing runs
    for i in range(10):
        q.submit(Job("design", f"a{i}"), "alice")
    q.submit(Job("design", "b0"), "bob")
    q.submit(Job("design", "b1"), "bob")
    order = [j.run_id for j in q.order()]
    assert order[:5] == ["a0", "b0", "a1", "b1", "a2"] and order[5:] == [f"a{i}" for i in range(3, 10)]
    assert q.queued()[0].run_id == "a0" and q.queued()[-1].run_id == "b1"  # submission order is kept too
    assert q.position(Job("design", "b0")) == {"position": 2, "ahead": 1, "queued": 12}
    assert q.position(Job("design", "zz")) is None
    # once Alice has had her turn (a start), Bob's oldest comes first, even though hers is older
    with q._cond:
        q._tick += 1
        q._served["alice"] = q._tick
    assert [j.run_id for j in q.order()][:3] == ["b0", "a0", "b1"]
    assert q.discard(Job("design", "b0")) and q.position(Job("design", "b1")) == {"position": 1, "ahead": 0,
                                                                                 "queued": 11}
    q.shutdown(timeout_s=0)


def test_queue_position_limits_and_cancel_isolation(tmp_path: Path) -> None:
    app = team_app(tmp_path / "ws")
    alice, bob = signed_in(app, ALICE), signed_in(app, BOB)
    a_pics, b_pics = pictures(alice), pictures(bob)
    a_runs = [new_run(alice, a_pics).json()["id"] for _ in range(3)]
    b_run = new_run(bob, b_pics).json()
    assert b_run["queue"] == {"position": 2, "ahead": 1, "queued": 4}  # after Alice's first, not her third
    third = alice.get(f"/api/runs/{a_runs[2]}").json()
    assert third["status"] == "queued" and third["queue"] == {"position": 4, "ahead": 3, "queued": 4}
    # the per-user limit: Alice's fifth waiting design is refused (429), Bob still has room
    assert new_run(alice, a_pics).status_code == 201
    r = new_run(alice, a_pics)
    assert r.status_code == 429, r.text
    assert "--max-queued-per-user 4" in r.json()["error"] and "cancel one" in r.json()["error"]
    assert DEFAULT_MAX_QUEUED_PER_USER == 4
    assert len(alice.get("/api/runs").json()) == 4  # the refused one left no run behind
    dup = bob.post(f"/api/runs/{b_run['id']}/duplicate", json={})
    assert dup.status_code == 201
    # a designer's cancel never touches another's run
    assert bob.post(f"/api/runs/{a_runs[0]}/cancel").status_code == 404
    assert alice.get(f"/api/runs/{a_runs[0]}").json()["status"] == "queued"
    assert bob.post(f"/api/runs/{b_run['id']}/cancel").json()["status"] == "cancelled"
    assert [alice.get(f"/api/runs/{i}").json()["status"] for i in a_runs] == ["queued"] * 3
    # Bob's duplicate moves up; Alice's first is still first
    assert alice.get(f"/api/runs/{a_runs[0]}").json()["queue"]["position"] == 1
    assert bob.get(f"/api/runs/{dup.json()['id']}").json()["queue"] == {"position": 2, "ahead": 1, "queued": 5}
    # a cancel makes room: Alice can queue again, and a resume counts against her share as a new run does
    assert alice.post(f"/api/runs/{a_runs[1]}/cancel").json()["status"] == "cancelled"
    assert new_run(alice, a_pics).status_code == 201
    r = alice.post(f"/api/runs/{a_runs[1]}/resume")
    assert r.status_code == 429 and "--max-queued-per-user" in r.json()["error"]
    opts = alice.get("/api/options").json()["limits"]
    assert opts["max_queued_per_user"] == 4 and opts["max_user_upload_bytes"] > opts["max_upload_bytes"]


def test_the_event_stream_tells_the_place_in_the_queue(tmp_path: Path) -> None:
    """A waiting run's status events carry its place, and a new one comes when the place changes."""
    import anyio

    from saucerfab.studio.app import _event_stream

    app = team_app(tmp_path / "ws")
    alice = signed_in(app, ALICE)
    pics = pictures(alice)
    first, second = (new_run(alice, pics).json()["id"] for _ in range(2))
    ws, queue = app.state.workspace, app.state.queue

    async def two_events() -> list[bytes]:
        stream = _event_stream(ws, second, ws.run_dir(second), lambda: queue.position(Job("design", second)))
        try:
            got = [await stream.__anext__()]
            queue.discard(Job("design", first))  # the run before it leaves the queue
            with anyio.fail_after(10):
                got.append(await stream.__anext__())
            return got
        finally:
            await stream.aclose()

    # in a thread of its own: the browser tests' Playwright may hold an event loop in this one
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        got = pool.submit(anyio.run, two_events).result(timeout=60)
    events = [json.loads(e.decode().split("data: ", 1)[1]) for e in got]
    assert [e["queue"] for e in events] == [{"position": 2, "ahead": 1, "queued": 2},
                                            {"position": 1, "ahead": 0, "queued": 1}]


def test_a_users_uploads_are_limited_in_total(tmp_path: Path) -> None:
    pics = [subject_png(i, 64) for i in range(4)]
    limit = sum(len(p) for p in pics[:2]) + 10  # room for two of the pictures
    app = team_app(tmp_path / "ws", max_user_upload_bytes=limit)
    alice, bob = signed_in(app, ALICE), signed_in(app, BOB)
    upload(alice, pics[0], "direct", "a.png")
    upload(alice, pics[1], "direct", "b.png")
    r = alice.post("/api/uploads?role=direct&name=c.png", content=pics[2])
    assert r.status_code == 413, r.text
    assert "--max-user-upload-mb" in r.json()["error"] and "your uploads take" in r.json()["error"]
    assert upload(bob, pics[2], "direct", "c.png")["id"]  # each designer has their own share
    assert not list((tmp_path / "ws" / "users" / "alice" / "uploads" / ".incoming").iterdir())


# --------------------------------------------------------------------------- a full disk


def test_a_full_disk_during_an_upload_or_a_new_run_keeps_nothing_half_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import saucerfab.studio.workspace as workspace

    app = team_app(tmp_path / "ws")
    alice = signed_in(app, ALICE, raise_server_exceptions=False)
    pics = pictures(alice)
    mine = tmp_path / "ws" / "users" / "alice" / "uploads"
    before = sorted(p.name for p in mine.iterdir())

    def full(*a: Any, **k: Any) -> None:
        raise ENOSPC

    monkeypatch.setattr(workspace, "write_bytes_atomic", full)  # the thumbnail of a new upload
    r = alice.post("/api/uploads?role=direct&name=d.png", content=subject_png(7))
    assert r.status_code == 500 and "No space left on device" in r.json()["error"]
    assert "free some space" in r.json()["error"]
    assert sorted(p.name for p in mine.iterdir()) == before and not list((mine / ".incoming").iterdir())
    monkeypatch.undo()
    monkeypatch.setattr(workspace, "write_json", full)  # the record of a new run
    r = new_run(alice, pics)
    assert r.status_code == 500 and "No space left on device" in r.json()["error"]
    assert not [p for p in (tmp_path / "ws" / "runs").iterdir()]  # no run folder without its record
    monkeypatch.undo()
    assert new_run(alice, pics).status_code == 201


def test_a_full_disk_during_a_design_fails_it_resumably(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The worker's design job in this process (the same code as in a worker process): the save of the design
    finds the disk full; the run is failed with the reason, no design folder is left, the checkpoint is kept,
    and a resume with space again finishes it."""
    import saucerfab.optimize.pipeline as pipeline
    from saucerfab.studio import worker

    class Alive:
        def gone(self) -> bool:
            return False

    app = team_app(tmp_path / "ws")
    alice = signed_in(app, ALICE)
    run_id = new_run(alice, pictures(alice)).json()["id"]
    ws = app.state.workspace
    ws.update_run(run_id, lambda rec: rec.update(status="running"))
    real = pipeline.save_design

    def full_disk(design: Any, folder: Any, **kw: Any) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(Path(folder) / "texture.png"))

    monkeypatch.setattr(pipeline, "save_design", full_disk)
    worker._design_job(ws, run_id, Alive())  # type: ignore[arg-type]
    rec = ws.read_run(run_id)
    folder = ws.runs / run_id
    assert rec["status"] == "failed" and "No space left on device" in rec["error"], rec
    assert str(ws.root) not in rec["error"]  # the workspace's path is not shown to the client
    assert not (folder / "design").exists() and (folder / ".design.checkpoint" / "state.npz").is_file()
    monkeypatch.setattr(pipeline, "save_design", real)
    assert alice.post(f"/api/runs/{run_id}/resume").json()["status"] == "queued"
    ws.update_run(run_id, lambda rec: rec.update(status="running"))
    worker._design_job(ws, run_id, Alive())  # type: ignore[arg-type]
    assert ws.read_run(run_id)["status"] == "done" and (folder / "design" / "design.json").is_file()


# --------------------------------------------------------------------------- a restart


def test_a_restart_mid_queue_requeues_the_waiting_and_leaves_the_running_resumable(tmp_path: Path) -> None:
    app = team_app(tmp_path / "ws", jobs=1)
    with TestClient(app, base_url=LOCAL):  # the lifespan: the queue runs
        alice, bob = signed_in(app, ALICE), signed_in(app, BOB)
        a_pics, b_pics = pictures(alice), pictures(bob)
        long_id = alice.post("/api/runs", json={**a_pics, **LONG}).json()["id"]
        waiting = [new_run(bob, b_pics).json()["id"], new_run(alice, a_pics).json()["id"]]
        wait_in_stage(alice, long_id)
    # the server stopped: the running design is interrupted (its checkpoint saved), the others still queued
    again = team_app(tmp_path / "ws", jobs=1)
    alice, bob = signed_in(again, ALICE), signed_in(again, BOB)
    rec = alice.get(f"/api/runs/{long_id}").json()
    assert rec["status"] == "interrupted" and "resume" in rec["error"]
    assert (tmp_path / "ws" / "runs" / long_id / ".design.checkpoint" / "state.npz").is_file()
    assert [c.get(f"/api/runs/{i}").json()["status"] for c, i in zip((bob, alice), waiting)] == ["queued"] * 2
    with TestClient(again, base_url=LOCAL):  # started again: the queued ones are queued again, with their owners
        for c, i in zip((bob, alice), waiting):
            assert wait_status(c, i, ("done", "failed"), timeout_s=120)["status"] == "done"
        assert alice.post(f"/api/runs/{long_id}/resume").json()["status"] == "queued"
        alice.post(f"/api/runs/{long_id}/cancel")


# --------------------------------------------------------------------------- a Dask cluster


@pytest.fixture(scope="module")
def local_cluster() -> Any:
    distributed = pytest.importorskip("distributed")
    # threads in this process: quick to start; each job is a child process of the worker all the same
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as c:
        yield c


def test_the_jobs_run_on_a_dask_cluster(tmp_path: Path, local_cluster: Any) -> None:
    from saucerfab.studio.cluster import DaskCluster

    Workspace(tmp_path / "ws")
    cluster = DaskCluster(local_cluster.scheduler_address, tmp_path / "ws")  # the probe passes: same filesystem
    try:
        assert cluster.slots() == 1
        app = team_app(tmp_path / "ws", cluster=cluster, grace_s=20)
        with TestClient(app, base_url=LOCAL):
            alice = signed_in(app, ALICE)
            run_id = new_run(alice, pictures(alice)).json()["id"]
            done = wait_status(alice, run_id, ("done", "failed", "cancelled"), timeout_s=90)
            assert done["status"] == "done", done
            assert alice.post(f"/api/runs/{run_id}/exports", json={"printer": "j55"}).status_code == 202
            for _ in range(600):
                entry = alice.get(f"/api/runs/{run_id}").json()["exports"]["j55"]
                if entry["status"] not in ("queued", "running"):
                    break
                time.sleep(0.1)
            assert entry["status"] == "done", entry
            assert alice.get(f"/api/runs/{run_id}/exports/j55.zip").content[:2] == b"PK"
            assert (tmp_path / "ws" / "runs" / run_id / "worker.log").is_file()  # written by the cluster's job
            # a cancel reaches the job on the cluster (its .stop file): SIGINT, the checkpoint saved, cancelled
            long_id = alice.post("/api/runs", json={**pictures(alice), **LONG}).json()["id"]
            wait_in_stage(alice, long_id, timeout_s=60)
            assert alice.post(f"/api/runs/{long_id}/cancel").json()["status"] == "cancelling"
            rec = wait_status(alice, long_id, ("cancelled", "failed", "done"), timeout_s=60)
            assert rec["status"] == "cancelled", rec
            assert (tmp_path / "ws" / "runs" / long_id / ".design.checkpoint" / "state.npz").is_file()
    finally:
        cluster.close()


def test_a_cluster_whose_workers_do_not_see_the_workspace_is_refused(
    tmp_path: Path, local_cluster: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    import saucerfab.studio.cluster as cl
    from saucerfab.errors import ConfigError

    def elsewhere(root: str, name: str) -> str:  # a worker on another machine: the probe file is not there
        raise FileNotFoundError(errno.ENOENT, "No such file or directory", f"{root}/{name}")

    monkeypatch.setattr(cl, "_probe", elsewhere)
    Workspace(tmp_path / "ws")
    with pytest.raises(ConfigError, match="does not see the studio's workspace") as exc:
        cl.DaskCluster(local_cluster.scheduler_address, tmp_path / "ws")
    assert "same path" in str(exc.value)
    assert not list((tmp_path / "ws").glob(".probe-*"))
    with pytest.raises(ConfigError, match="tcp://HOST:PORT"):
        cl.DaskCluster("localhost:1", tmp_path / "ws")


def test_a_lone_designer_has_no_share_of_the_queue_to_keep_to(tmp_path: Path) -> None:
    """The per-user limit is a team's rule: one token (or --no-auth) queues as many designs as it likes."""
    from studio_helpers import TOKEN

    app = create_app(tmp_path / "ws", auth=Auth.shared(TOKEN), max_queued_per_user=2)
    me = signed_in(app)
    pics = pictures(me)
    assert [new_run(me, pics).status_code for _ in range(4)] == [201] * 4
