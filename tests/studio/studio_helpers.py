"""Shared helpers of the studio's tests: tiny pictures, tiny design options, waiting for a run.

Designs in these tests are tiny (a 12 x 12 grid, 32 px renders, a few
iterations) so the real worker processes they start finish in seconds.
"""

from __future__ import annotations

import io
import struct
import time
import zlib
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
#: the studio answers to loopback names only (saucerfab/studio/guard.py); the test client's default is 'testserver'
LOCAL = "http://127.0.0.1:8000"
#: the token the API tests sign in with (test_studio_auth.py is about signing in; the others sign in and go on)
TOKEN = "the-studio-tests-token-0123456789"
#: the header a script signs in with
AUTH = {"Authorization": f"token {TOKEN}"}
HEART = REPO / "samples" / "direct_heart.png"
STAR = REPO / "samples" / "reflected_star.png"

#: the smallest design the method runs on (verify off: it adds a trial export and a ray trace)
TINY = {"resolution": 12, "image_size": 32, "max_iters": 4, "verify": False, "record_times": False}
#: a design long enough to be caught in its first stage (cancel, restart): about 3 s of optimisation on a quiet
#: machine after the first iteration (at 16 x 16, 48 px it was under 1 s, and on a loaded CI machine the run
#: sometimes ended before the cancel reached it)
LONG = {"resolution": 48, "image_size": 160, "max_iters": 300, "verify": False, "record_times": False}


def png(rgb: np.ndarray) -> bytes:
    """PNG bytes of an (H, W, 3|4) uint8 array."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def subject_png(seed: int, size: int = 48) -> bytes:
    """A distinct small picture: a coloured disc on white (a clear subject), different for each seed."""
    yy, xx = np.mgrid[0:size, 0:size]
    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 255, np.uint8)
    r = size * (0.2 + 0.2 * rng.random())
    disc = (yy - size / 2) ** 2 + (xx - size / 2) ** 2 < r * r
    img[disc] = rng.integers(0, 160, 3)
    return png(img)


def bomb_png(width: int = 30000, height: int = 30000) -> bytes:
    """A tiny PNG whose header claims ``width`` x ``height`` pixels (IHDR patched, CRC fixed)."""
    data = bytearray(png(np.zeros((4, 4, 3), np.uint8)))
    ihdr = data.index(b"IHDR")
    data[ihdr + 4 : ihdr + 12] = struct.pack(">II", width, height)
    crc = zlib.crc32(bytes(data[ihdr : ihdr + 17])) & 0xFFFFFFFF
    data[ihdr + 17 : ihdr + 21] = struct.pack(">I", crc)
    return bytes(data)


def npy(a: np.ndarray) -> bytes:
    """``.npy`` file bytes of an array."""
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def signed_in(app: Any, token: str = TOKEN, **client_args: Any) -> Any:
    """A test client of ``app`` signed in as a browser is: the token once in the URL (``?token=``, as the studio
    prints it), then the session cookie the answer sets. ``client_args`` go to ``TestClient``."""
    from starlette.testclient import TestClient

    client = TestClient(app, base_url=LOCAL, **client_args)
    r = client.get(f"/?token={token}", headers={"Accept": "text/html"}, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/", (r.status_code, r.text[:200])
    assert client.cookies, "signing in set no cookie"
    return client


def upload(client: Any, data: bytes, role: str, name: str) -> dict[str, Any]:
    """POST an upload; returns its record (asserting 201)."""
    r = client.post(f"/api/uploads?role={role}&name={name}", content=data)
    assert r.status_code == 201, r.text
    return r.json()


def pair(client: Any) -> dict[str, str]:
    """Upload the bundled heart and star; returns {"direct": id, "reflected": id}."""
    return {"direct": upload(client, HEART.read_bytes(), "direct", "heart.png")["id"],
            "reflected": upload(client, STAR.read_bytes(), "reflected", "star.png")["id"]}


def wait_status(client: Any, run_id: str, wanted: tuple[str, ...], timeout_s: float = 90.0) -> dict[str, Any]:
    """Poll GET /api/runs/{id} until its status is one of ``wanted``; returns the run."""
    deadline = time.monotonic() + timeout_s
    while True:
        run = client.get(f"/api/runs/{run_id}").json()
        if run.get("status") in wanted:
            return run
        if time.monotonic() > deadline:
            raise AssertionError(f"run {run_id} still {run.get('status')} after {timeout_s} s: {run}")
        time.sleep(0.1)


def wait_in_stage(client: Any, run_id: str, timeout_s: float = 60.0) -> dict[str, Any]:
    """Poll until the run's progress shows its first optimisation stage under way; returns the run."""
    deadline = time.monotonic() + timeout_s
    while True:
        run = client.get(f"/api/runs/{run_id}").json()
        prog = run.get("progress") or {}
        if run.get("status") == "running" and prog.get("stage_index") == 0 and prog.get("iteration", 0) > 0:
            return run
        if run.get("status") not in ("queued", "running") or time.monotonic() > deadline:
            raise AssertionError(f"run {run_id} never got into a stage: {run}")
        time.sleep(0.05)


def sse_events(lines: Any) -> Any:
    """(event, data) pairs from an event stream's lines."""
    import json

    kind = None
    for line in lines:
        if line.startswith("event: "):
            kind = line[7:]
        elif line.startswith("data: ") and kind:
            yield kind, json.loads(line[6:])
            kind = None
