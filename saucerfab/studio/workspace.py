"""The studio's workspace folder: layout, run ids, run records, uploads (schema ``saucerfab.studio/1``).

The layout is in ``saucerfab/studio/README.md``. Everything here is plain
blocking file work, safe from several threads and processes at once:

* every file is written atomically (:mod:`saucerfab.files.fileio`);
* a run's record (``run.json``) is only changed through :meth:`Workspace.update_run`,
  which holds the run's lock (``flock`` on ``runs/<id>/.lock``, so the server's
  threads and the worker processes take turns) around its read-modify-write;
* nothing from a client names a path: run ids are checked against
  :data:`RUN_ID_RE`, upload ids against :data:`UPLOAD_ID_RE`, and uploads are
  stored under their content hash with a sanitised name.

Users (issue 39): a run records its ``owner``; each user's uploads are their
own (:meth:`Workspace.for_user`), so one designer's file names and pictures
never show in another's page. The shared user (:data:`SHARED_USER`: the one
user of a single token or of ``--no-auth``, and the admin of a token file)
keeps the folders of before: ``uploads/``, and the runs that record no owner.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import os
import re
import secrets
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from saucerfab.errors import ConfigError, ImageError, SaucerfabError, ShapeError
from saucerfab.files.fileio import atomic_dir, write_bytes_atomic, write_text_atomic

#: the workspace marker's schema
SCHEMA = "saucerfab.studio/1"
#: a run record's schema
RUN_SCHEMA = "saucerfab.studio.run/1"
#: a run id: UTC time of creation and 4 random hex digits ("20261202-071500-3fa2")
RUN_ID_RE = re.compile(r"\A[0-9]{8}-[0-9]{6}-[0-9a-f]{4}\Z")
#: an upload id: the first 16 hex digits of the file's sha256
UPLOAD_ID_RE = re.compile(r"\A[0-9a-f]{16}\Z")
#: the roles an upload can play: a picture per view, its mask, or the base shape
ROLES = ("direct", "reflected", "reflected2", "direct_mask", "reflected_mask", "reflected2_mask", "shape")
#: run statuses after which nothing more happens on their own
FINAL = ("done", "failed", "cancelled", "interrupted")
#: run statuses while a worker has (or will have) the run
ACTIVE = ("queued", "running", "cancelling")
#: the largest upload accepted by default, bytes (streamed; the rest is refused with 413)
MAX_UPLOAD_BYTES = 64 << 20
#: the most bytes of uploads one user may keep by default (``--max-user-upload-mb``; more is refused with 413)
MAX_USER_UPLOAD_BYTES = 1 << 30
#: thumbnails' longest side, pixels
THUMB_PX = 256
#: the longest display name kept for an upload, characters
MAX_NAME_CHARS = 80
#: the largest run.json / upload.json read, bytes (a damaged or hostile file is not loaded whole)
MAX_RECORD_BYTES = 4 << 20
#: the user of a single token (or of no sign-in) and the admin of a token file: sees every run; owns the runs
#: that record no owner (made before users) and the uploads in ``uploads/``
SHARED_USER = "admin"
#: a user name: letters, digits, '.', '_' and '-', starting with a letter or digit (it names a folder)
USER_RE = re.compile(r"\A[A-Za-z0-9][A-Za-z0-9._-]{0,63}\Z")

_MAGIC = ((b"\x89PNG\r\n\x1a\n", ".png"), (b"\xff\xd8\xff", ".jpg"), (b"\x93NUMPY", ".npy"))


class StudioError(SaucerfabError):
    """A request the studio refuses; ``status`` is the HTTP status the API answers with."""

    status = 400


class NotFound(StudioError):
    """An unknown run, upload, export or file (404)."""

    status = 404


class Conflict(StudioError):
    """The run is not in a state that allows this (409)."""

    status = 409


class TooLarge(StudioError):
    """An upload over the size limit (413)."""

    status = 413


class TooMany(StudioError):
    """A user's share of the queue is full (429: try again once one of their runs has started)."""

    status = 429


def now_iso() -> str:
    """The current UTC time as ``2026-12-02T07:15:00Z``."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def owner_of(rec: dict[str, Any]) -> str:
    """The user a run belongs to (a run made before users belongs to the shared user)."""
    owner = rec.get("owner")
    return owner if isinstance(owner, str) and owner else SHARED_USER


def no_such_run(run_id: str) -> NotFound:
    """The error of a run that is not there, or is another user's (the same words: it does not say which)."""
    return NotFound(f"no run {run_id!r} in this workspace (deleted, or from another workspace)")


def sanitise_name(name: str | None, default: str = "picture") -> str:
    """A client's file name made safe to store and show: its last path part, plain characters, short.

    ``"../../etc/passwd"`` -> ``"passwd"``; ``"Été photo (1).PNG"`` -> ``"t photo (1).PNG"``.
    """
    base = re.split(r"[\\/]", str(name or ""))[-1]
    clean = re.sub(r"[^A-Za-z0-9._ ()+-]", "", base).strip(" .")
    return clean[:MAX_NAME_CHARS] or default


def _read_json(path: Path) -> dict[str, Any] | None:
    """A JSON object file, or None when it is missing, too large or damaged."""
    try:
        if path.stat().st_size > MAX_RECORD_BYTES:
            return None
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    return d if isinstance(d, dict) else None


def write_json(path: Path, doc: dict[str, Any]) -> None:
    """``doc`` as indented JSON, written atomically."""
    write_text_atomic(path, json.dumps(doc, indent=2, default=str) + "\n")


_THREAD_LOCKS: dict[str, threading.Lock] = {}


@contextlib.contextmanager
def _flock(path: Path) -> Iterator[None]:
    """Hold ``flock`` on ``path`` (blocking: a record update takes milliseconds), re-taken if the file was replaced.

    Raises:
        FileNotFoundError: the folder of ``path`` is gone (the run was deleted).
    """
    try:
        import fcntl
    except ImportError:  # no flock (Windows): one server process, so a lock per path within it serves
        with _THREAD_LOCKS.setdefault(str(path), threading.Lock()):
            if not path.parent.is_dir():
                raise FileNotFoundError(str(path)) from None
            yield
        return
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            held = os.fstat(fd)
            try:
                now = os.stat(path)
            except FileNotFoundError:
                now = None
        except BaseException:
            os.close(fd)
            raise
        if now is not None and (now.st_dev, now.st_ino) == (held.st_dev, held.st_ino):
            break
        os.close(fd)
        if now is None and not path.parent.is_dir():
            raise FileNotFoundError(str(path))
    try:
        yield
    finally:
        os.close(fd)


class Workspace:
    """One studio workspace folder (see the module docstring).

    Args:
        root: the folder; created (with ``studio.json``) when ``create`` and it is new or empty.
        create: make the folder a workspace if it is not one yet.

    Raises:
        ConfigError: ``root`` is a file, or a non-empty folder that is not a workspace
            (the studio would mix its folders with someone's files).
    """

    def __init__(self, root: str | os.PathLike[str], *, create: bool = True) -> None:
        self.root = Path(root).expanduser().resolve()
        marker = self.root / "studio.json"
        if create and not marker.is_file():
            if self.root.exists() and not self.root.is_dir():
                raise ConfigError(f"workspace {str(self.root)!r} is a file; give a folder for the studio's designs")
            if self.root.is_dir() and any(p.name != ".lock" for p in self.root.iterdir()):
                raise ConfigError(
                    f"workspace {str(self.root)!r} is a folder with other files in it (no studio.json); give a "
                    "new or empty folder, or an earlier studio workspace"
                )
            self.root.mkdir(parents=True, exist_ok=True)
            write_json(marker, {"schema": SCHEMA})
        doc = _read_json(marker)
        if doc is None or doc.get("schema") != SCHEMA:
            raise ConfigError(
                f"{str(marker)!r} is not a {SCHEMA} workspace marker (found {doc and doc.get('schema')!r}); "
                "give another folder for --workspace"
            )
        self.uploads = self.root / "uploads"
        self.runs = self.root / "runs"
        self.uploads.mkdir(exist_ok=True)
        self.runs.mkdir(exist_ok=True)
        #: whether upload ids are looked up in every user's uploads too (the shared user's view: the admin)
        self.all_uploads = True

    def for_user(self, user: str) -> Workspace:
        """This workspace as ``user`` sees its uploads: the shared user's are ``uploads/`` (and it finds
        every user's), another user's ``users/<user>/uploads/``; runs are shared (their records say whose).

        Raises:
            ConfigError: a malformed user name (names come from the token file, checked there).
        """
        if user == SHARED_USER:
            return self
        if not USER_RE.match(user):
            raise ConfigError(f"user name {user[:40]!r} is not letters, digits, '.', '_' and '-'")
        view = copy.copy(self)
        view.uploads = self.root / "users" / user / "uploads"
        view.uploads.mkdir(parents=True, exist_ok=True)
        view.all_uploads = False
        return view

    # ------------------------------------------------------------------ paths

    def scrub(self, message: str) -> str:
        """A message with the workspace's absolute path taken out (clients see paths relative to it)."""
        return message.replace(str(self.root) + os.sep, "").replace(str(self.root), "the workspace")

    def run_dir(self, run_id: str) -> Path:
        """The folder of run ``run_id``.

        Raises:
            NotFound: a malformed id, or no such run.
        """
        if not isinstance(run_id, str) or not RUN_ID_RE.match(run_id):
            raise NotFound(f"no run {str(run_id)[:40]!r}: run ids look like 20261202-071500-3fa2")
        d = self.runs / run_id
        if not (d / "run.json").is_file():
            raise no_such_run(run_id)
        return d

    def upload_dir(self, upload_id: str) -> Path:
        """The folder of upload ``upload_id``.

        Raises:
            NotFound: a malformed id, or no such upload.
        """
        if not isinstance(upload_id, str) or not UPLOAD_ID_RE.match(upload_id):
            raise NotFound(f"no upload {str(upload_id)[:40]!r}: upload ids are 16 hex digits")
        d = self.uploads / upload_id
        if (d / "upload.json").is_file():
            return d
        if self.all_uploads:  # the shared user's view finds every user's uploads (the admin resumes their runs)
            for other in sorted((self.root / "users").glob(f"*/uploads/{upload_id}/upload.json")):
                return other.parent
        raise NotFound(f"no upload {upload_id!r} in this workspace; upload the file again")

    def upload_record(self, upload_id: str) -> dict[str, Any]:
        """The record (``upload.json``) of an upload."""
        rec = _read_json(self.upload_dir(upload_id) / "upload.json")
        if rec is None:
            raise NotFound(f"upload {upload_id!r} has a damaged upload.json; upload the file again")
        return rec

    def upload_path(self, upload_id: str) -> Path:
        """The stored file of an upload."""
        rec = self.upload_record(upload_id)
        return self.upload_dir(upload_id) / sanitise_name(rec.get("name"))

    # ------------------------------------------------------------------ run records

    @contextlib.contextmanager
    def locked(self, run_id: str) -> Iterator[Path]:
        """Hold run ``run_id``'s lock for a ``with`` block; yields its folder."""
        d = self.run_dir(run_id)
        try:
            with _flock(d / ".lock"):
                if not (d / "run.json").is_file():  # deleted while we waited
                    raise NotFound(f"run {run_id!r} was deleted")
                yield d
        except FileNotFoundError:
            raise NotFound(f"run {run_id!r} was deleted") from None

    def read_run(self, run_id: str) -> dict[str, Any]:
        """The record of run ``run_id`` (``run.json``, written atomically, so read without the lock)."""
        rec = _read_json(self.run_dir(run_id) / "run.json")
        if rec is None:
            raise NotFound(f"run {run_id!r} has a damaged run.json")
        return rec

    def update_run(self, run_id: str, change: Callable[[dict[str, Any]], None]) -> dict[str, Any]:
        """Read, ``change`` in place and write back run ``run_id``'s record under its lock; returns it.

        ``change`` may raise (e.g. :class:`Conflict`) to leave the record as it was.
        """
        with self.locked(run_id) as d:
            rec = self.read_run(run_id)
            change(rec)
            write_json(d / "run.json", rec)
            return rec

    def create_run(self, options: dict[str, Any], title: str, owner: str = SHARED_USER) -> dict[str, Any]:
        """A new queued run of ``owner`` with ``options`` (the client's, upload ids and all); returns its record."""
        for _ in range(100):
            run_id = time.strftime("%Y%m%d-%H%M%S", time.gmtime()) + "-" + secrets.token_hex(2)
            d = self.runs / run_id
            try:
                d.mkdir()  # exclusive: two tabs creating runs in the same second get two ids
            except FileExistsError:
                continue
            rec = {
                "schema": RUN_SCHEMA, "id": run_id, "title": title, "owner": owner, "created": now_iso(),
                "created_ns": time.time_ns(),  # orders runs made within one second (two tabs)
                "options": options,
                "status": "queued", "error": None, "started": None, "finished": None, "exports": {},
            }
            try:
                write_json(d / "run.json", rec)
            except BaseException:  # a full disk: no folder without a record is left behind
                shutil.rmtree(d, ignore_errors=True)
                raise
            return rec
        raise StudioError("could not make a new run id; try again")  # 100 collisions: never in practice

    def list_runs(self) -> list[dict[str, Any]]:
        """Every run's record, newest first (a folder without a readable run.json is left out)."""
        out = []
        for d in self.runs.iterdir():
            if RUN_ID_RE.match(d.name):
                rec = _read_json(d / "run.json")
                if rec is not None and rec.get("id") == d.name:
                    out.append(rec)
        # the id starts with the time to the second; created_ns orders the runs within one second
        out.sort(key=lambda r: (r["id"][:15], r.get("created_ns") or 0, r["id"]), reverse=True)
        return out

    def delete_run(self, run_id: str) -> None:
        """Remove run ``run_id``'s folder.

        Raises:
            Conflict: the run is queued, running or cancelling (cancel it first).
        """
        with self.locked(run_id) as d:
            rec = self.read_run(run_id)
            if rec.get("status") in ACTIVE:
                raise Conflict(f"run {run_id} is {rec.get('status')}; cancel it first, then delete it")
            busy = [p for p, e in rec.get("exports", {}).items() if e.get("status") in ("queued", "running")]
            if busy:
                raise Conflict(f"run {run_id} is exporting for {', '.join(busy)}; wait until it is done")
            lit = [p for p, e in rec.get("exports", {}).items()
                   if isinstance(e.get("lit"), dict) and e["lit"].get("status") in ("queued", "running")]
            if lit:
                raise Conflict(f"run {run_id} is rendering its export for {', '.join(lit)} under the room light; "
                               "wait until it is done")
            # moved aside first (atomic), so no one sees a half-removed run
            trash = self.runs / f".deleted-{run_id}-{secrets.token_hex(4)}"
            os.replace(d, trash)
        shutil.rmtree(trash, ignore_errors=True)

    def startup_scan(self) -> tuple[list[str], list[tuple[str, str]]]:
        """After a (re)start: mark what was running as interrupted; return what is to be queued again.

        A run ``running`` or ``cancelling`` when the server stopped is
        ``interrupted`` (its checkpoint keeps the finished stages; ``resume``
        continues); an export ``running`` then is ``failed`` (start it again),
        and so is an export's verify under the room light (``lit``; ask for it again).
        Leftovers of interrupted uploads and deletes are removed.

        Returns:
            (run ids of queued designs, oldest first; (run id, printer) of queued exports). The queued
            verifies under the room light are :meth:`queued_lits`.
        """
        incoming = [*(self.uploads / ".incoming").glob("*"), *self.root.glob("users/*/uploads/.incoming/*")]
        for p in list(self.runs.glob(".deleted-*")) + incoming:
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
        designs: list[str] = []
        exports: list[tuple[str, str]] = []

        def scan(rec: dict[str, Any]) -> None:
            if rec.get("status") in ("running", "cancelling"):
                rec["status"] = "interrupted"
                rec["error"] = ("the studio stopped while this design was running; resume continues after the "
                                "last stage that had finished")
                rec["finished"] = now_iso()
            for printer, e in rec.get("exports", {}).items():
                if e.get("status") == "running":
                    e.update(status="failed", error="the studio stopped during this export; start it again")
                elif e.get("status") == "queued":
                    exports.append((rec["id"], printer))
                lit = e.get("lit")
                if isinstance(lit, dict) and lit.get("status") == "running":
                    lit.update(status="failed", progress=None, error="the studio stopped during this verify under "
                               "the room light; ask for it again")
            if rec.get("status") == "queued":
                designs.append(rec["id"])

        for rec in reversed(self.list_runs()):
            try:
                self.update_run(rec["id"], scan)
            except NotFound:
                continue
        return designs, exports

    def queued_lits(self) -> list[tuple[str, str]]:
        """(run id, printer) of the exports whose verify under the room light is queued, oldest run first
        (after :meth:`startup_scan`: queued again at a start)."""
        return [(rec["id"], printer) for rec in reversed(self.list_runs())
                for printer, e in rec.get("exports", {}).items()
                if isinstance(e, dict) and isinstance(e.get("lit"), dict) and e["lit"].get("status") == "queued"]

    # ------------------------------------------------------------------ uploads

    def upload_bytes(self) -> int:
        """Bytes of the uploads in this view's folder (the user's; ``uploads/`` for the shared user), as their
        records say (the stored file's size)."""
        total = 0
        for rec_path in self.uploads.glob("*/upload.json"):
            rec = _read_json(rec_path)
            if rec is not None and isinstance(rec.get("bytes"), int):
                total += rec["bytes"]
        return total

    def incoming(self) -> tuple[int, Path]:
        """A new temporary file under the workspace for an upload being received: (open fd, path)."""
        folder = self.uploads / ".incoming"
        folder.mkdir(exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix="upload-", suffix=".part", dir=folder)
        return fd, Path(tmp)

    def store_upload(self, tmp: Path, role: str, name: str | None, *, max_pixels: int) -> dict[str, Any]:
        """Validate a received file and keep it as an upload; returns its record (``upload.json``).

        The file is read with the library's own loaders (the picture with
        :func:`saucerfab.imaging.images.load_image` and its pixel limit, a shape with
        :func:`saucerfab.model.heightfield.load_shape`), so what is refused here is
        what ``saucerfab design`` refuses, in its words. ``tmp`` is removed.

        Raises:
            StudioError: an unknown role. ImageError, ShapeError: a bad file.
        """
        try:
            if role not in ROLES:
                raise StudioError(f"unknown upload role {role!r}; use one of {', '.join(ROLES)}")
            with open(tmp, "rb") as fh:
                head = fh.read(16)
                digest = hashlib.sha256(head)
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    digest.update(chunk)
            sha = digest.hexdigest()
            shown = sanitise_name(name, "shape" if role == "shape" else "picture")
            kind = "shape" if role == "shape" else "image"
            suffix = next((s for magic, s in _MAGIC if head.startswith(magic)), None)
            if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
                suffix = ".webp"
            # the stored name keeps the client's stem and takes the suffix of what the bytes are
            stem = Path(shown).stem or kind
            final_name = sanitise_name(stem + (suffix or Path(shown).suffix or ".bin"))
            typed = tmp.with_name(tmp.stem + (suffix or ".bin"))
            os.replace(tmp, typed)
            tmp = typed
            try:
                info, thumb = (_check_shape(tmp, suffix) if kind == "shape" else _check_image(tmp, role, max_pixels))
            except (ImageError, ShapeError) as exc:
                text = str(exc).replace(repr(str(tmp)), repr(shown)).replace(str(tmp), shown)
                raise type(exc)(text) from None
            upload_id = sha[:16]
            rec = {"id": upload_id, "name": final_name, "role": role, "kind": kind,
                   "bytes": tmp.stat().st_size, **info, "sha256": sha, "created": now_iso()}
            dest = self.uploads / upload_id
            try:
                with atomic_dir(dest, overwrite=False) as build:
                    os.replace(tmp, build / final_name)
                    write_bytes_atomic(build / "thumb.png", thumb)
                    write_json(build / "upload.json", rec)
            except (FileExistsError, OSError):
                if not (dest / "upload.json").is_file():
                    raise
                # the same bytes were uploaded before (or just now, in another tab): one copy is kept
                old = self.upload_record(upload_id)
                if old.get("kind") != kind or old.get("role") != role:
                    old.update(role=role, kind=kind, **info)
                    write_bytes_atomic(dest / "thumb.png", thumb)
                    write_json(dest / "upload.json", old)
                rec = old
            return rec
        finally:
            tmp.unlink(missing_ok=True)


def _thumb_png(rgb: np.ndarray) -> bytes:
    """PNG bytes of an (H, W, 3) float picture in [0, 1], its longest side at most :data:`THUMB_PX`."""
    from PIL import Image

    from saucerfab.files.imageio import png_bytes

    im = Image.fromarray(np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8))
    im.thumbnail((THUMB_PX, THUMB_PX), Image.Resampling.LANCZOS)
    return png_bytes(np.asarray(im.convert("RGB")))


def checker(h: int, w: int, cell: int = 8) -> np.ndarray:
    """(h, w, 3) light grey checkerboard: what transparency is shown over."""
    yy, xx = np.mgrid[0:h, 0:w]
    light = ((yy // cell + xx // cell) % 2).astype(np.float32)
    return np.repeat((0.8 + 0.15 * light)[..., None], 3, axis=2)


def _check_image(path: Path, role: str, max_pixels: int) -> tuple[dict[str, Any], bytes]:
    """Load a picture or mask as the design would: (width/height, thumbnail PNG)."""
    from saucerfab.imaging.images import DEFAULT_MAX_BYTES, load_image

    img = load_image(path, max_pixels=max_pixels, max_bytes=DEFAULT_MAX_BYTES)
    rgb = img.rgb
    if img.alpha is not None:
        if not role.endswith("_mask") and float(img.alpha.max()) <= 1.0 / 255:
            # a design of an invisible picture is a plain saucer: surely not what was meant
            raise ImageError(
                f"image {str(path)!r} has no visible content: every pixel is fully transparent. Export the "
                "picture again with its layers visible, or pick another picture"
            )
        a = img.alpha[..., None]
        rgb = rgb * a + checker(*img.alpha.shape) * (1 - a)
    w, h = img.size
    return {"width": w, "height": h}, _thumb_png(rgb)


def _check_shape(path: Path, suffix: str | None) -> tuple[dict[str, Any], bytes]:
    """Load a base-shape heightfield as the design would: (width/height, grey thumbnail PNG)."""
    from saucerfab.files.imageio import npy_header
    from saucerfab.model.heightfield import load_shape

    if suffix not in (".png", ".npy"):
        raise ShapeError(
            f"shape file {str(path)!r} is not a PNG or .npy file; a base shape is an 8/16-bit grayscale PNG "
            "(white = high) or a 2-D .npy array of heights"
        )
    w = h = 0
    if suffix == ".npy":
        try:
            shape, _ = npy_header(path)
        except (OSError, ValueError) as exc:
            raise ShapeError(f"{str(path)!r} is not a valid .npy file: {exc}") from None
        if len(shape) == 2:
            h, w = int(shape[0]), int(shape[1])
    else:
        from PIL import Image

        with contextlib.suppress(OSError, ValueError, Image.DecompressionBombError):
            with Image.open(path, formats=["PNG"]) as im:
                w, h = im.size
    # The height range depends on the run's height_scale, checked when a run is made; here
    # the file is read at the smallest scale, so only its form (2-D, numbers, finite) is judged.
    heights = load_shape(path, THUMB_PX // 2, height_scale=1e-12)
    lo, hi = float(heights.min()), float(heights.max())
    grey = (heights - lo) / (hi - lo) if hi > lo else np.full_like(heights, 0.5)
    # row 0 of the grid is the saucer's near edge: flipped so the picture reads as a map from above
    return {"width": w, "height": h}, _thumb_png(np.repeat(grey[::-1, :, None], 3, axis=2))
