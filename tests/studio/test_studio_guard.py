"""The studio's Host and Origin checks (saucerfab/studio/guard.py): DNS rebinding and cross-site requests.

A page on another site must not be able to start, cancel or delete designs
through the user's browser, nor read the workspace after re-pointing its own
name at 127.0.0.1. Tested in-process on the real app (no worker is started:
every refused request is refused before any route runs).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from starlette.testclient import TestClient

from saucerfab.studio.app import create_app
from saucerfab.studio.guard import _host_name


@pytest.fixture()
def app(tmp_path: Path):  # type: ignore[no-untyped-def]
    return create_app(tmp_path / "ws")


@pytest.mark.parametrize("base", ["http://127.0.0.1:8000", "http://localhost:8000", "http://[::1]:8000"])
def test_loopback_names_are_served(app, base: str) -> None:  # type: ignore[no-untyped-def]
    r = TestClient(app, base_url=base).get("/api/runs")
    assert r.status_code == 200 and r.json() == []


def test_a_rebound_name_is_refused(app) -> None:  # type: ignore[no-untyped-def]
    """DNS rebinding: the browser sends the attacker's name as Host."""
    for base in ("http://evil.example:8000", "http://testserver", "http://127.0.0.1.evil.example:8000"):
        r = TestClient(app, base_url=base).get("/api/runs")
        assert r.status_code == 421, base
        assert "answers to" in r.json()["error"] and "Traceback" not in r.text


def test_a_cross_site_post_is_refused(app) -> None:  # type: ignore[no-untyped-def]
    c = TestClient(app, base_url="http://127.0.0.1:8000")
    for origin in ("http://evil.example", "http://127.0.0.1:9999", "null"):
        r = c.post("/api/uploads?role=direct&name=a.png", content=b"x", headers={"Origin": origin})
        assert r.status_code == 403, origin
        assert "another site" in r.json()["error"]
        r = c.delete("/api/runs/20261202-071500-3fa2", headers={"Origin": origin})
        assert r.status_code == 403, origin
    # a GET from another origin is not refused by the guard (the browser keeps its answer from that page)
    assert c.get("/api/runs", headers={"Origin": "http://evil.example"}).status_code == 200
    # the studio's own page: same origin passes the guard (and then gets the route's own answer)
    r = c.post("/api/uploads?role=direct&name=a.png", content=b"not a picture", headers={"Origin": "http://127.0.0.1:8000"})
    assert r.status_code == 400 and "another site" not in r.json()["error"]
    # no Origin at all (curl, scripts): not a browser's cross-site request
    assert c.post("/api/uploads?role=direct&name=a.png", content=b"not a picture").status_code == 400


def test_shared_on_the_network_any_host_but_still_same_origin(tmp_path: Path) -> None:
    c = TestClient(create_app(tmp_path / "ws", allowed_hosts=None), base_url="http://studio.lan:8000")
    assert c.get("/api/runs").status_code == 200
    r = c.post("/api/uploads?role=direct&name=a.png", content=b"x", headers={"Origin": "http://evil.example"})
    assert r.status_code == 403


@pytest.mark.parametrize(("host", "name"), [
    ("127.0.0.1:8000", "127.0.0.1"), ("LOCALHOST", "localhost"), ("[::1]:8000", "::1"), ("::1", "::1"),
    ("evil.example:80", "evil.example"),
])
def test_host_name(host: str, name: str) -> None:
    assert _host_name(host) == name
