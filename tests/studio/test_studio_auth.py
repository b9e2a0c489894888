"""Signing in to the studio and each user's own designs (issue 39; saucerfab/studio/auth.py).

In-process on the real app (starlette.testclient; no worker is started, runs
stay queued), except the log test, which serves through uvicorn with the
studio's own logging. Users: ``admin`` (sees everyone's designs), ``alice``
and ``bob`` (each their own).
"""

from __future__ import annotations

import io
import json
import logging
import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from live_studio import free_port
from starlette.routing import Mount, Route
from starlette.testclient import TestClient
from studio_helpers import HEART, LOCAL, TINY, TOKEN, pair, signed_in, upload

from saucerfab.cli import main
from saucerfab.errors import ConfigError
from saucerfab.studio.app import create_app
from saucerfab.studio.auth import (
    MIN_TOKEN_CHARS,
    SESSION_MAX_AGE_S,
    TOKEN_ENV,
    Auth,
    User,
    read_token_file,
    redact,
    resolve_auth,
)
from saucerfab.studio.workspace import SHARED_USER

ADMIN, ALICE, BOB = "admin-token-0123456789abcdef", "alice-token-0123456789abcdef", "bob-token-0123456789abcdef"
TEAM = {"admin": ADMIN, "alice": ALICE, "bob": BOB}
#: a run id that is nobody's (well formed, as an id guesser would try)
GUESS = "20261202-071500-3fa2"
NO_TOKEN = "open the URL the studio printed"


@pytest.fixture
def team(tmp_path: Path):  # type: ignore[no-untyped-def]
    return create_app(tmp_path / "ws", auth=Auth(TEAM, "--token-file team.txt"))


def as_user(app: Any, token: str) -> TestClient:
    return signed_in(app, token)


def anonymous(app: Any) -> TestClient:
    return TestClient(app, base_url=LOCAL)


@pytest.fixture
def alices_run(team) -> dict[str, Any]:  # type: ignore[no-untyped-def]
    """A run of alice's (queued: no worker runs here), with an export entry as a done run would have."""
    alice = as_user(team, ALICE)
    rec = alice.post("/api/runs", json={**pair(alice), **TINY}).json()
    assert rec["owner"] == "alice", rec
    ws = team.state.workspace
    doc = json.loads((ws.runs / rec["id"] / "run.json").read_text())
    doc["exports"] = {"j55": {"status": "done", "files": []}}
    (ws.runs / rec["id"] / "run.json").write_text(json.dumps(doc))
    (ws.runs / rec["id"] / "exports").mkdir()
    (ws.runs / rec["id"] / "exports" / "j55.zip").write_bytes(b"PK\x05\x06" + bytes(18))
    return rec


def routes(run_id: str, upload_id: str) -> list[tuple[str, str, Any]]:
    """Every route of the studio (method, URL, JSON body or None), for a run and an upload.

    In this order a queued run is cancelled before its event stream is read (the stream of a run that is
    still to run would not end: the test client reads a whole answer)."""
    r = f"/api/runs/{run_id}"
    return [
        ("GET", "/", None), ("GET", "/static/studio.js", None), ("GET", "/api/options", None),
        ("GET", "/api/session", None), ("POST", "/api/uploads?role=direct&name=a.png", None),
        ("GET", "/api/samples/direct_heart", None), ("POST", "/api/samples/direct_heart", None),
        ("GET", f"/api/uploads/{upload_id}/thumb.png", None), ("GET", f"/api/uploads/{upload_id}/fitted.png", None),
        ("GET", "/api/runs", None), ("POST", "/api/runs", {}), ("GET", r, None), ("DELETE", r, None),
        ("POST", f"{r}/cancel", None), ("GET", f"{r}/events", None), ("POST", f"{r}/resume", None),
        ("POST", f"{r}/duplicate", {}), ("GET", f"{r}/files/run.json", None), ("GET", f"{r}/viewer", None),
        ("POST", f"{r}/exports", {"printer": "j55"}), ("GET", f"{r}/exports/j55.zip", None),
        ("GET", f"{r}/exports/j55", None), ("POST", f"{r}/exports/j55/lit", None),
    ]


def _call(client: TestClient, method: str, url: str, body: Any, **kw: Any) -> Any:
    return client.request(method, url, json=body, **kw) if body is not None else client.request(method, url, **kw)


def _template(url: str) -> str:
    """A route's URL with its ids put back as the route's parameters, to compare with the app's routes."""
    url = url.split("?", 1)[0]
    url = re.sub(r"/api/runs/[^/]+", "/api/runs/{id}", url)
    url = re.sub(r"/api/uploads/[0-9a-f]{16}", "/api/uploads/{id}", url)
    url = re.sub(r"/api/samples/\w+", "/api/samples/{name}", url)
    url = re.sub(r"/files/.*", "/files/{path:path}", url)
    return re.sub(r"/exports/j55(\.zip|/lit)?$", lambda m: "/exports/{printer}" + (m.group(1) or ""), url)


# --------------------------------------------------------------------------- every route asks for the token


def test_without_the_token_every_route_answers_401(team, alices_run) -> None:  # type: ignore[no-untyped-def]
    upload_id = alices_run["options"]["direct"]
    table = routes(alices_run["id"], upload_id)
    covered = {(m, _template(u)) for m, u, _ in table}
    for route in team.routes:  # a route added to the app must be added to the table above
        if isinstance(route, Route) and not route.path.startswith(("/login", "/logout")):
            for method in route.methods - {"HEAD"}:
                assert (method, route.path) in covered, (method, route.path)
        elif isinstance(route, Mount):
            assert any(u.startswith(route.path + "/") for _, u, _ in table), route.path
    nobody = anonymous(team)
    forged = anonymous(team)
    forged.cookies.set(next(iter(as_user(team, ALICE).cookies.keys())), "alice.1.0000")
    for client, headers in ((nobody, {}), (nobody, {"Authorization": "token not-a-token-of-this-studio"}),
                            (nobody, {"Authorization": f"Basic {ALICE}"}), (forged, {})):
        for method, url, body in table:
            r = _call(client, method, url, body, headers=headers)
            assert r.status_code == 401, (method, url, headers, r.status_code)
            if url == "/":
                assert r.headers["content-type"].startswith("text/html") and 'action="/login"' in r.text
                assert "default-src 'none'" in r.headers["content-security-policy"]
            else:
                assert NO_TOKEN in r.json()["error"], (url, r.text)
    # with the token (the header, as a script sends it) every route gets its own answer
    for method, url, body in table:
        r = _call(nobody, method, url, body, headers={"Authorization": f"token {ALICE}"})
        assert r.status_code not in (401, 403, 404), (method, url, r.status_code, r.text[:200])
    r = nobody.get("/api/runs", headers={"Authorization": f"Bearer {BOB}"})
    assert r.status_code == 200 and r.json() == []  # Bearer as well; bob sees none of alice's


def test_the_token_in_the_url_signs_in_once_and_leaves_the_address(team) -> None:  # type: ignore[no-untyped-def]
    c = anonymous(team)
    html = {"Accept": "text/html,application/xhtml+xml"}
    r = c.get(f"/?token={ALICE}&x=1", headers=html, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/?x=1"  # the same address without the token
    cookie = r.headers["set-cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Path=/" in cookie and "Secure" not in cookie
    assert ALICE not in cookie and "token" not in cookie.split(";")[0]  # the cookie never holds the token
    assert c.get("/api/session").json() == {"auth": True, "user": "alice", "admin": False}
    assert c.get("/").status_code == 200 and "studio.js" in c.get("/").text  # the page, on the cookie alone
    # a path that starts with two slashes is not sent off to another host
    r = anonymous(team).get(f"{LOCAL}//evil.example/?token={ALICE}", headers=html, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"].startswith("/evil.example"), r.headers["location"]
    # a script's ?token= (no HTML asked for) is answered at once, no redirect, no cookie
    s = anonymous(team)
    r = s.get(f"/api/session?token={BOB}", follow_redirects=False)
    assert r.status_code == 200 and r.json()["user"] == "bob" and not s.cookies
    # a wrong token in the URL: the sign-in page says so, and a cookie does not stand in for it
    r = c.get("/?token=not-the-token-0123456789", headers=html)
    assert r.status_code == 401 and "The token in this address is not this studio&#x27;s" in r.text
    assert c.get("/api/runs?token=not-the-token-0123456789").status_code == 401


def test_the_sign_in_form_and_signing_out(team) -> None:  # type: ignore[no-untyped-def]
    c = anonymous(team)
    r = c.get("/login?next=/api/session")
    assert r.status_code == 200 and 'name="next" value="/api/session"' in r.text
    r = c.post("/login", data={"token": "not-the-token-0123456789", "next": "/"})
    assert r.status_code == 401 and "That is not this studio&#x27;s token" in r.text and not c.cookies
    r = c.post("/login", data={"token": BOB, "next": "/api/session"})
    assert r.status_code == 200 and r.json()["user"] == "bob"  # signed in, and sent where it was going
    for bad in ("//evil.example/", "https://evil.example/", "/\\evil.example"):
        r = anonymous(team).post("/login", data={"token": BOB, "next": bad}, follow_redirects=False)
        assert r.status_code == 303 and r.headers["location"] == "/", bad
    assert c.post("/login", content=b"token=" + bytes(8000)).status_code == 413
    r = c.post("/logout", follow_redirects=False)
    assert r.status_code == 303 and "Max-Age=0" in r.headers["set-cookie"]
    assert c.get("/api/session").status_code == 401
    assert c.get("/logout").status_code == 405  # signing out is a POST (a link elsewhere cannot do it)


def test_a_forged_expired_or_revoked_cookie_is_refused(team, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    auth: Auth = team.state.auth
    now = time.time()
    alice = auth.check_token(ALICE)
    assert alice is not None and auth.check_token("alice") is None
    value = auth.session_value(alice, now)
    assert auth.session_user(value, now) == alice
    name, issued, mac = value.rsplit(".", 2)
    assert auth.session_user(f"bob.{issued}.{mac}", now) is None  # another user's name on alice's MAC
    assert auth.session_user(f"{name}.{int(issued) + 1}.{mac}", now) is None
    assert auth.session_user(value, now + SESSION_MAX_AGE_S + 1) is None  # expired
    assert auth.session_user("garbage", now) is None and auth.session_user("a.b.c.d", now) is None
    changed = Auth({**TEAM, "alice": "alice-new-token-0123456789"})
    assert changed.session_user(value, now) is None  # a new token signs the old sessions out
    assert changed.session_user(Auth(TEAM).session_value(changed.check_token(BOB), now), now) is not None
    # the cookie of one studio is not another's (cookies do not tell ports apart)
    other = create_app(tmp_path / "other", auth=Auth(TEAM))
    assert set(as_user(team, ALICE).cookies.keys()).isdisjoint(as_user(other, ALICE).cookies.keys())


def test_a_cross_site_request_with_the_cookie_is_refused(team, alices_run) -> None:  # type: ignore[no-untyped-def]
    alice = as_user(team, ALICE)
    rid = alices_run["id"]
    evil = {"Origin": "http://evil.example"}
    for method, url in (("POST", f"/api/runs/{rid}/cancel"), ("DELETE", f"/api/runs/{rid}"),
                        ("POST", "/api/uploads?role=direct&name=a.png"), ("POST", "/logout"), ("POST", "/login")):
        r = alice.request(method, url, headers=evil)
        assert r.status_code == 403 and "another site" in r.json()["error"], (method, url, r.text)
    assert alice.get(f"/api/runs/{rid}").json()["status"] == "queued"  # nothing was done
    r = alice.post(f"/api/runs/{rid}/cancel", headers={"Origin": LOCAL})  # the studio's own page
    assert r.status_code == 200 and r.json()["status"] == "cancelled"


# --------------------------------------------------------------------------- each user's own designs


def test_a_user_cannot_reach_another_users_runs(team, alices_run) -> None:  # type: ignore[no-untyped-def]
    bob = as_user(team, BOB)
    rid = alices_run["id"]
    upload_id = alices_run["options"]["direct"]
    assert bob.get("/api/runs").json() == []
    for run_id in (rid, GUESS):  # alice's run and a run that is nobody's answer alike
        for method, url, body in routes(run_id, upload_id):
            if f"/api/runs/{run_id}" not in url:
                continue
            r = _call(bob, method, url, body)
            assert r.status_code == 404, (method, url, r.status_code)
            assert r.json()["error"] == f"no run {run_id!r} in this workspace (deleted, or from another workspace)"
    # her pictures neither: not shown, not usable in a run of his
    assert bob.get(f"/api/uploads/{upload_id}/thumb.png").status_code == 404
    assert bob.get(f"/api/uploads/{upload_id}/fitted.png").status_code == 404
    r = bob.post("/api/runs", json={**alices_run["options"]})
    assert r.status_code == 404 and "upload" in r.json()["error"]
    # and alice still has all of it
    alice = as_user(team, ALICE)
    assert [x["id"] for x in alice.get("/api/runs").json()] == [rid]
    assert "owner" not in alice.get("/api/runs").json()[0]  # a user's list is theirs: no owner column
    assert alice.get(f"/api/runs/{rid}").json()["status"] == "queued"
    assert alice.get(f"/api/uploads/{upload_id}/thumb.png").status_code == 200


def test_uploads_are_each_users_own(team) -> None:  # type: ignore[no-untyped-def]
    """The same picture uploaded by two users is kept for each under their own name."""
    alice, bob = as_user(team, ALICE), as_user(team, BOB)
    a = upload(alice, HEART.read_bytes(), "direct", "my-heart.png")
    b = upload(bob, HEART.read_bytes(), "direct", "valentine.png")
    assert a["id"] == b["id"] and (a["name"], b["name"]) == ("my-heart.png", "valentine.png")
    root = team.state.workspace.root
    assert (root / "users" / "alice" / "uploads" / a["id"] / "my-heart.png").is_file()
    assert (root / "users" / "bob" / "uploads" / b["id"] / "valentine.png").is_file()
    assert not (root / "uploads" / a["id"]).exists()  # the shared user's uploads/ holds none of theirs


def test_the_admin_sees_every_run_with_its_owner(team, alices_run) -> None:  # type: ignore[no-untyped-def]
    bob = as_user(team, BOB)
    bobs = bob.post("/api/runs", json={**pair(bob), **TINY}).json()
    ws = team.state.workspace
    old = ws.create_run({"direct": "0" * 16}, "from before users")  # as the studio before issue 39 wrote it
    doc = json.loads((ws.runs / old["id"] / "run.json").read_text())
    del doc["owner"]
    (ws.runs / old["id"] / "run.json").write_text(json.dumps(doc))
    admin = as_user(team, ADMIN)
    assert admin.get("/api/session").json() == {"auth": True, "user": "admin", "admin": True}
    listed = {x["id"]: x["owner"] for x in admin.get("/api/runs").json()}
    assert listed == {alices_run["id"]: "alice", bobs["id"]: "bob", old["id"]: SHARED_USER}
    assert admin.get(f"/api/runs/{old['id']}").json()["owner"] == SHARED_USER  # a run of before: the admin's
    assert bob.get(f"/api/runs/{old['id']}").status_code == 404
    # the admin acts on a user's run, and copies it (the copy's pictures are found in alice's uploads)
    thumb = admin.get(f"/api/uploads/{alices_run['options']['direct']}/thumb.png")
    assert thumb.status_code == 200
    r = admin.post(f"/api/runs/{alices_run['id']}/duplicate", json={"shape": "bowl"})
    assert r.status_code == 201 and r.json()["owner"] == "admin", r.text
    assert admin.post(f"/api/runs/{alices_run['id']}/cancel").json()["status"] == "cancelled"
    assert admin.delete(f"/api/runs/{alices_run['id']}").status_code == 200
    assert as_user(team, ALICE).get("/api/runs").json() == []


def test_one_token_is_one_shared_user_who_sees_the_runs_of_before(tmp_path: Path) -> None:
    app = create_app(tmp_path / "ws", auth=Auth.shared(TOKEN))
    ws = app.state.workspace
    old = ws.create_run({"direct": "0" * 16}, "from before")
    doc = json.loads((ws.runs / old["id"] / "run.json").read_text())
    del doc["owner"]
    (ws.runs / old["id"] / "run.json").write_text(json.dumps(doc))
    c = signed_in(app)
    assert c.get("/api/session").json() == {"auth": True, "user": SHARED_USER, "admin": True}
    assert [x["id"] for x in c.get("/api/runs").json()] == [old["id"]]
    # no sign-in at all (--no-auth): the same shared user, and no sign-in routes
    open_app = create_app(tmp_path / "ws")
    c = TestClient(open_app, base_url=LOCAL)
    assert c.get("/api/session").json() == {"auth": False, "user": None, "admin": True}
    assert [x["id"] for x in c.get("/api/runs").json()] == [old["id"]]
    assert c.get("/login").status_code == 404


# --------------------------------------------------------------------------- where the token comes from


def _resolve(token: str | None = None, token_file: Any = None, no_auth: bool = False, host: str = "127.0.0.1",
             env: dict[str, str] | None = None) -> tuple[Auth, str | None]:
    return resolve_auth(token, token_file, no_auth, host=host, loopback=host in ("127.0.0.1", "::1"), env=env or {})


def test_token_sources(tmp_path: Path) -> None:
    auth, made = _resolve()
    assert made is not None and len(made) >= 43
    assert auth.check_token(made) == User(SHARED_USER, admin=True)
    assert _resolve()[1] != made  # a new one each start
    auth, made = _resolve(token=ADMIN)
    assert made is None and auth.check_token(ADMIN) is not None
    auth, made = _resolve(env={TOKEN_ENV: BOB}, host="0.0.0.0")
    assert made is None and auth.check_token(BOB) is not None
    assert _resolve(env={TOKEN_ENV: ""})[1] is not None  # an empty variable is no token
    auth, _ = _resolve(no_auth=True, host="0.0.0.0")
    assert not auth.required
    f = tmp_path / "team.txt"
    f.write_text(f"# the bureau's designers\n\nadmin:{ADMIN}\nalice : {ALICE}\n  bob:{BOB}  \n")
    auth, _ = _resolve(token_file=f, host="0.0.0.0")
    assert auth.tokens == TEAM
    f.write_text(f"{ALICE}\n")
    assert read_token_file(f).tokens == {SHARED_USER: ALICE}  # one token, no user: the shared user


@pytest.mark.parametrize(("kw", "words"), [
    ({"token": ADMIN, "env": {TOKEN_ENV: BOB}}, "given twice (--token and $SAUCERFAB_STUDIO_TOKEN)"),
    ({"token": ADMIN, "token_file": "team.txt"}, "given twice (--token and --token-file)"),
    ({"no_auth": True, "token": ADMIN}, "--no-auth and --token contradict each other"),
    ({"no_auth": True, "env": {TOKEN_ENV: BOB}}, "unset $SAUCERFAB_STUDIO_TOKEN"),
    ({"host": "0.0.0.0"}, "--host 0.0.0.0 serves the studio to the network, so it needs a token"),
    ({"host": "192.168.1.4"}, "or --no-auth"),
    ({"token": "short"}, f"5 characters; a token must be at least {MIN_TOKEN_CHARS}"),
    ({"token": "with a space in it, long enough"}, "holds a space"),
    ({"env": {TOKEN_ENV: "ünïcode-token-0123456789"}}, "outside printable ASCII"),
])
def test_contradictory_and_weak_tokens_are_refused(kw: dict[str, Any], words: str) -> None:
    with pytest.raises(ConfigError) as info:
        _resolve(**kw)
    assert words in str(info.value), str(info.value)


@pytest.mark.parametrize(("text", "words"), [
    ("", "holds no token"),
    ("# only a comment\n", "holds no token"),
    ("alice:short\n", "user 'alice'"),
    (f"alice:{ALICE}\n{BOB}\n", "line 2 has no user"),
    (f"alice:{ALICE}\nAlice:{BOB}\n", "names user 'Alice' again"),
    (f"alice:{ALICE}\nbob:{ALICE}\n", "the same token"),
    (f"../etc:{ALICE}\n", "is not letters, digits"),
    (f"alice:{ALICE}\n" + "x" * 70_000, "over 65,536 bytes"),
    ("".join(f"u{i}:token-of-user-number-{i:06d}\n" for i in range(1001)), "up to 1000"),
])
def test_bad_token_files_are_refused(tmp_path: Path, text: str, words: str) -> None:
    f = tmp_path / "team.txt"
    f.write_text(text)
    with pytest.raises(ConfigError) as info:
        read_token_file(f)
    assert words in str(info.value), str(info.value)
    with pytest.raises(ConfigError, match="cannot read"):
        read_token_file(tmp_path / "missing.txt")
    (tmp_path / "bin").write_bytes(b"\xff\xfe\x00bad")
    with pytest.raises(ConfigError, match="not UTF-8"):
        read_token_file(tmp_path / "bin")


@pytest.fixture
def no_serving(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """``saucerfab studio`` through its CLI with uvicorn's serving stubbed out; the served apps are listed."""
    import uvicorn

    monkeypatch.delenv(TOKEN_ENV, raising=False)
    served: list[Any] = []
    monkeypatch.setattr(uvicorn.Server, "run", lambda self: served.append(self.config))
    return served


def test_the_command_prints_its_url_with_a_new_token_once(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                          no_serving: list[Any]) -> None:
    port = str(free_port())
    main(["studio", "--workspace", str(tmp_path / "ws"), "--port", port])
    out, err = capsys.readouterr()
    assert "warning" not in err  # a token on loopback: nothing to warn of
    urls = re.findall(rf"http://127\.0\.0\.1:{port}/\?token=([\w-]+)", out)
    assert len(urls) == 1 and out.count(urls[0]) == 1 and len(urls[0]) >= 43, out
    assert no_serving[-1].app.state.auth.check_token(urls[0]) is not None  # the URL's token is the app's
    main(["studio", "--workspace", str(tmp_path / "ws"), "--port", port, "--token", ADMIN])
    out, _ = capsys.readouterr()
    assert ADMIN not in out and "?token=" not in out and "sign in with the token of --token" in out


@pytest.mark.parametrize(("args", "words"), [
    (["--token", ADMIN, "--no-auth"], "--no-auth and --token contradict each other"),
    (["--host", "0.0.0.0"], "needs a token"),
    (["--token", "tiny"], "at least 16"),
    (["--token-file", "missing.txt"], "cannot read --token-file"),
])
def test_the_command_refuses_contradictions(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                            no_serving: list[Any], args: list[str], words: str) -> None:
    assert main(["studio", "--workspace", str(tmp_path / "ws"), "--port", "0", *args]) == 2
    assert words in capsys.readouterr().err
    assert not no_serving and not (tmp_path / "ws").exists()  # refused before anything was made or served


def test_the_command_on_the_network_with_a_token_file(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      no_serving: list[Any]) -> None:
    f = tmp_path / "team.txt"
    f.write_text("".join(f"{u}:{t}\n" for u, t in TEAM.items()))
    main(["studio", "--workspace", str(tmp_path / "ws"), "--host", "0.0.0.0", "--port", "0", "--token-file", str(f)])
    out, err = capsys.readouterr()
    assert "each user with their own token" in out and "warning" not in err
    assert not any(t in out + err for t in TEAM.values())
    assert no_serving[-1].app.state.auth.tokens == TEAM


# --------------------------------------------------------------------------- the token never reaches a log


def test_redact() -> None:
    assert redact("GET /?token=abc-DEF_1&x=2 HTTP/1.1") == "GET /?token=[redacted]&x=2 HTTP/1.1"
    assert redact("/api/runs?x=1&TOKEN=abc") == "/api/runs?x=1&TOKEN=[redacted]"
    assert redact("/api/runs?mytoken=abc") == "/api/runs?mytoken=abc"


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[str, io.StringIO]]:
    """The studio under uvicorn with its own logging, at INFO (the access log on, as a service might run it):
    (its address, what its log handlers write)."""
    import uvicorn

    from saucerfab.studio.server import server_config

    app = create_app(tmp_path / "ws", auth=Auth(TEAM))
    server = uvicorn.Server(server_config(app, "127.0.0.1", 0, log_level="info"))
    logged = io.StringIO()
    for name in ("uvicorn", "uvicorn.access"):  # the studio's handlers (and their filters), writing here
        for handler in logging.getLogger(name).handlers:
            if isinstance(handler, logging.StreamHandler):
                handler.setStream(logged)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "the server did not start"
        time.sleep(0.05)
    try:
        yield f"http://127.0.0.1:{server.servers[0].sockets[0].getsockname()[1]}", logged
    finally:
        server.should_exit = True
        thread.join(timeout=30)


def test_a_token_in_a_url_is_not_logged(served: tuple[str, io.StringIO]) -> None:
    import httpx2 as httpx

    base, log = served
    with httpx.Client(base_url=base, timeout=30, follow_redirects=True) as c:
        r = c.get(f"/?token={ALICE}&x=1", headers={"Accept": "text/html"})  # a browser: redirected, cookie set
        assert r.status_code == 200 and r.url.path == "/" and "token" not in str(r.url)
        assert c.get(f"/api/runs?token={BOB}").status_code == 200  # a script's URL
        assert c.get("/api/runs?token=wrong-token-0123456789").status_code == 401
        c.cookies.clear()
        assert c.get("/api/runs", headers={"Authorization": f"token {ADMIN}"}).status_code == 200
    time.sleep(0.2)  # the access log is written after each answer
    logged = log.getvalue()
    assert "GET /?token=[redacted]&x=1 HTTP/1.1" in logged and "GET /api/runs?token=[redacted]" in logged, logged
    for secret in (ALICE, BOB, ADMIN, "wrong-token-0123456789"):
        assert secret not in logged, logged
