"""The studio's workspace: layout, ids, records under their lock, uploads through the library's loaders, restarts."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest
from studio_helpers import HEART, bomb_png, npy, png, subject_png

from saucerfab.errors import ConfigError, ImageError, ShapeError
from saucerfab.studio.workspace import (
    RUN_ID_RE,
    Conflict,
    NotFound,
    StudioError,
    Workspace,
    sanitise_name,
)


def _store(ws: Workspace, data: bytes, role: str = "direct", name: str = "pic.png") -> dict:
    fd, tmp = ws.incoming()
    with open(fd, "wb") as fh:
        fh.write(data)
    return ws.store_upload(tmp, role, name, max_pixels=64_000_000)


def test_layout_and_refusals(tmp_path: Path) -> None:
    ws = Workspace(tmp_path / "ws")
    assert json.loads((ws.root / "studio.json").read_text()) == {"schema": "saucerfab.studio/1"}
    assert ws.uploads.is_dir() and ws.runs.is_dir()
    Workspace(ws.root)  # an existing workspace opens again
    other = tmp_path / "photos"
    other.mkdir()
    (other / "holiday.jpg").write_bytes(b"x")
    with pytest.raises(ConfigError, match="other files"):
        Workspace(other)
    with pytest.raises(ConfigError, match="is a file"):
        Workspace(other / "holiday.jpg")


@pytest.mark.parametrize("given, kept", [
    ("../../etc/passwd", "passwd"), ("C:\\Users\\me\\a b.png", "a b.png"), ("", "picture"), ("...", "picture"),
    (".hidden.png", "hidden.png"), ("x" * 300 + ".png", "x" * 80),
])
def test_sanitise_name(given: str, kept: str) -> None:
    assert sanitise_name(given) == kept


def test_run_ids_and_records(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    a = ws.create_run({"direct": "0" * 16}, "a")
    b = ws.create_run({"direct": "1" * 16}, "b")
    assert RUN_ID_RE.match(a["id"]) and a["id"] != b["id"]
    assert a["status"] == "queued" and a["schema"] == "saucerfab.studio.run/1"
    assert [r["id"] for r in ws.list_runs()] == [b["id"], a["id"]]  # newest first, even within one second
    for bad in ("../etc", "20261202-071500-3fa", "20261202-071500-3fa2/..", "", "20991202-071500-3fa2"):
        with pytest.raises(NotFound):
            ws.run_dir(bad)


def test_record_updates_do_not_interleave(tmp_path: Path) -> None:
    """Eight threads add 1 to a counter 25 times each through update_run: none of the 200 is lost."""
    ws = Workspace(tmp_path)
    run_id = ws.create_run({}, "t")["id"]

    def bump(rec: dict) -> None:
        rec["n"] = rec.get("n", 0) + 1

    def work() -> None:
        for _ in range(25):
            ws.update_run(run_id, bump)

    threads = [threading.Thread(target=work) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert ws.read_run(run_id)["n"] == 200


def test_delete(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    run_id = ws.create_run({}, "t")["id"]
    with pytest.raises(Conflict, match="cancel it first"):
        ws.delete_run(run_id)
    ws.update_run(run_id, lambda r: r.update(status="done"))
    ws.delete_run(run_id)
    assert not (ws.runs / run_id).exists() and not list(ws.runs.iterdir())
    with pytest.raises(NotFound):
        ws.read_run(run_id)


def test_upload_stored_by_hash_with_thumbnail(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    rec = _store(ws, HEART.read_bytes(), name="../../My Heart.png")
    assert rec["name"] == "My Heart.png" and rec["kind"] == "image" and (rec["width"], rec["height"]) == (512, 512)
    d = ws.uploads / rec["id"]
    assert (d / "My Heart.png").read_bytes() == HEART.read_bytes()
    from PIL import Image

    with Image.open(d / "thumb.png") as im:
        assert max(im.size) <= 256
    again = _store(ws, HEART.read_bytes(), name="copy.png")
    assert again["id"] == rec["id"]  # one copy per content
    assert not list((ws.uploads / ".incoming").iterdir())  # no temporary left


def test_upload_name_takes_the_suffix_of_the_content(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    assert _store(ws, subject_png(1), name="photo.jpg")["name"] == "photo.png"


@pytest.mark.parametrize("data, role, words", [
    (b"hello, I am text", "direct", "not a PNG, JPEG or WebP"),
    (bomb_png(), "direct", "64,000,000 pixels"),
    (png(np.zeros((8, 8, 4), np.uint8)), "reflected", "fully transparent"),
    (b"", "direct", "empty"),
    (npy(np.zeros((4, 4, 4))), "shape", "2-D"),
    (npy(np.zeros((1, 9))), "shape", "at least 2x2"),
    (npy(np.array([[0.0, np.nan], [1, 2]])), "shape", "NaN"),
    (b"GIF89a....", "shape", "PNG or .npy"),
], ids=["text", "bomb", "transparent", "empty", "npy-3d", "npy-1-row", "npy-nan", "gif-shape"])
def test_bad_uploads_say_what_is_wrong(tmp_path: Path, data: bytes, role: str, words: str) -> None:
    ws = Workspace(tmp_path)
    with pytest.raises((ImageError, ShapeError)) as info:
        _store(ws, data, role=role, name="mine.png")
    text = str(info.value)
    assert words in text and "mine" in text
    assert str(ws.root) not in text and ".part" not in text  # no server path, no temporary name
    assert not list((ws.uploads / ".incoming").iterdir())
    assert [p.name for p in ws.uploads.iterdir()] == [".incoming"]


def test_shape_upload(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    rec = _store(ws, npy(np.linspace(0, 1, 20 * 30).reshape(20, 30)), role="shape", name="ridge.npy")
    assert rec["kind"] == "shape" and rec["name"] == "ridge.npy" and (rec["width"], rec["height"]) == (30, 20)
    with pytest.raises(StudioError, match="unknown upload role"):
        _store(ws, subject_png(2), role="nonsense")


def test_startup_scan(tmp_path: Path) -> None:
    ws = Workspace(tmp_path)
    ids = [ws.create_run({}, str(i))["id"] for i in range(4)]
    ws.update_run(ids[0], lambda r: r.update(status="running"))
    ws.update_run(ids[1], lambda r: r.update(status="cancelling"))
    ws.update_run(ids[3], lambda r: r.update(status="done", exports={
        "j55": {"status": "running"}, "bureau": {"status": "queued"}, "j850": {"status": "done"}}))
    (ws.runs / ".deleted-x").mkdir()
    designs, exports = ws.startup_scan()
    assert designs == [ids[2]] and exports == [(ids[3], "bureau")]
    for i in (0, 1):
        rec = ws.read_run(ids[i])
        assert rec["status"] == "interrupted" and "resume" in rec["error"]
    ex = ws.read_run(ids[3])["exports"]
    assert ex["j55"]["status"] == "failed" and ex["j850"]["status"] == "done"
    assert not (ws.runs / ".deleted-x").exists()
