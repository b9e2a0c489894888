"""The studio's ASGI app: the page, its static files and the JSON API of ``README.md``.

:func:`create_app` builds a Starlette app over a workspace. Handlers do file
work in Starlette's threadpool (``run_in_threadpool``) and never run a design
or an export themselves: those are jobs of :class:`~saucerfab.studio.jobs.JobQueue`,
started in the app's lifespan and stopped (workers SIGINTed, so their
checkpoints are saved) when it ends.

Every request signs in first (:mod:`saucerfab.studio.auth`, behind the
Host/Origin guard); the routes see the user, show each user their own runs
and uploads (the admin every run) and answer another user's run as an
unknown one (404: it does not say the run is there).

Errors: a :class:`~saucerfab.studio.workspace.StudioError` answers its own
status, any other :class:`~saucerfab.errors.SaucerfabError` (the library's
words for bad input) 400, and an unexpected fault 500 ``internal error``,
with the traceback in the server's log only. Every error body is ``{"error": "..."}``.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.requests import ClientDisconnect, Request
from starlette.responses import FileResponse, JSONResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from saucerfab.errors import SaucerfabError
from saucerfab.pages.labels import api_labels
from saucerfab.studio import options as opts
from saucerfab.studio.auth import USER_KEY, Auth, SignIn, User, login_routes, session_cookie_name
from saucerfab.studio.guard import LOOPBACK_NAMES, HostOriginGuard
from saucerfab.studio.jobs import DEFAULT_JOBS, DEFAULT_MAX_QUEUED_PER_USER, Job, JobQueue
from saucerfab.studio.lit import LIT_ACTIVE, lit_entry, queue_lit
from saucerfab.studio.results import SERVED_SUFFIXES, design_results, export_details, thumb_url, viewer_page
from saucerfab.studio.workspace import (
    FINAL,
    MAX_UPLOAD_BYTES,
    MAX_USER_UPLOAD_BYTES,
    ROLES,
    RUN_ID_RE,
    SHARED_USER,
    Conflict,
    NotFound,
    StudioError,
    TooLarge,
    Workspace,
    no_such_run,
    now_iso,
    owner_of,
)

log = logging.getLogger("saucerfab.studio")

#: the page's files (index.html, studio.js, studio.css), packaged
STATIC = Path(__file__).resolve().parents[1] / "data" / "studio"
#: how often the event stream looks at the run's files, seconds
EVENT_POLL_S = 0.25
#: a comment line this often keeps proxies and browsers from closing a quiet event stream, seconds
KEEPALIVE_S = 15.0
#: the largest JSON request body, bytes
MAX_JSON_BYTES = 1 << 20
#: sizes the fitted-picture preview may be asked for, pixels
FITTED_PX = (16, 1024)


def _json_response(doc: Any, status: int = 200) -> JSONResponse:
    return JSONResponse(doc, status_code=status, headers={"Cache-Control": "no-store"})


def _error(status: int, message: str) -> JSONResponse:
    return _json_response({"error": message}, status)


def sample_files() -> dict[str, tuple[Path, str]]:
    """The bundled sample pictures: name (file stem) -> (file, the role it plays in its first pair)."""
    from saucerfab.samples import PAIRS, SAMPLES

    out: dict[str, tuple[Path, str]] = {}
    for direct, reflected in PAIRS.values():
        for rel, role in ((direct, "direct"), (reflected, "reflected")):
            p = SAMPLES / rel
            if p.is_file():
                out.setdefault(p.stem, (p, role))
    return out


async def _body_json(request: Request) -> Any:
    """The request's JSON body (an empty body is ``{}``)."""
    body = b""
    async for chunk in request.stream():
        body += chunk
        if len(body) > MAX_JSON_BYTES:
            raise TooLarge(f"the request body is over {MAX_JSON_BYTES:,} bytes; options are a small JSON object")
    if not body.strip():
        return {}
    try:
        return json.loads(body)
    except (ValueError, RecursionError):
        raise StudioError("the request body is not valid JSON") from None


def create_app(
    workspace: str | os.PathLike[str],
    *,
    jobs: int = DEFAULT_JOBS,
    max_upload_bytes: int = MAX_UPLOAD_BYTES,
    max_pixels: int | None = None,
    grace_s: float | None = None,
    allowed_hosts: Sequence[str] | None = LOOPBACK_NAMES,
    auth: Auth | None = None,
    max_queued_per_user: int = DEFAULT_MAX_QUEUED_PER_USER,
    max_user_upload_bytes: int = MAX_USER_UPLOAD_BYTES,
    cluster: Any = None,
) -> Starlette:
    """The studio app over ``workspace`` (made a workspace if new or empty).

    Args:
        workspace: the workspace folder.
        jobs: designs and exports run at once (worker processes).
        max_upload_bytes: the largest upload, bytes (more is 413).
        max_pixels: the largest picture accepted, width x height
            (default: :data:`saucerfab.imaging.images.DEFAULT_MAX_PIXELS`).
        grace_s: seconds a cancelled worker has to stop before it is killed.
        allowed_hosts: the names accepted in a request's ``Host`` (loopback by
            default; None: any, for a studio shared on the network); requests
            from another site's page are refused either way
            (:mod:`saucerfab.studio.guard`).
        auth: the users and their tokens (:mod:`saucerfab.studio.auth`); None:
            no sign-in, every request is the shared user's (``--no-auth``).
        max_queued_per_user: designs one user may have waiting when the studio has several users (0: no
            limit; more is 429); a studio with one user (one token, ``--no-auth``) has no limit.
        max_user_upload_bytes: bytes of uploads one user may keep (more is 413).
        cluster: a connected :class:`saucerfab.studio.cluster.DaskCluster` the jobs run on
            (``--scheduler``); None: worker processes on this machine.
    """
    from saucerfab.imaging.images import DEFAULT_MAX_PIXELS

    ws = Workspace(workspace)
    auth = Auth(None, "--no-auth") if auth is None else auth
    # the share of the queue is a team's rule: a lone designer (one token, --no-auth) queues as before
    team = auth.tokens is not None and len(auth.tokens) > 1
    queue = JobQueue(ws, jobs=jobs, max_queued=max_queued_per_user if team else 0, cluster=cluster,
                     **({} if grace_s is None else {"grace_s": grace_s}))
    # one user's check of their share of the queue and the queuing it allows happen together (two tabs)
    queuing = anyio.Lock()
    pixels = DEFAULT_MAX_PIXELS if max_pixels is None else int(max_pixels)
    samples = sample_files()
    choices: dict[str, Any] = {}
    cookie = session_cookie_name(ws.root)

    # ------------------------------------------------------------------ who asks

    def _me(request: Request) -> User:
        return request.scope[USER_KEY]  # set by SignIn before any route runs

    def _uploads(request: Request) -> Workspace:
        """The workspace as the signed-in user sees its uploads."""
        return ws.for_user(_me(request).name)

    def _visible(request: Request) -> dict[str, Any]:
        """The record of the run the path names, when the signed-in user may see it; else the NotFound of a
        run that is not there (another user's run is not confirmed to exist, however its id was found)."""
        run_id, me = request.path_params["id"], _me(request)
        try:
            rec = ws.read_run(run_id)
        except NotFound:
            if me.admin or not RUN_ID_RE.match(run_id):
                raise
            raise no_such_run(run_id) from None  # a damaged record of another user's run says no more either
        if not me.sees(owner_of(rec)):
            raise no_such_run(run_id)
        return rec

    async def _run(request: Request) -> str:
        """The id of the run the path names, once :func:`_visible` let it through."""
        return str((await run_in_threadpool(_visible, request))["id"])

    # ------------------------------------------------------------------ page and options

    async def index(request: Request) -> Response:
        page = STATIC / "index.html"
        if not page.is_file():
            return _error(404, "the studio page is not installed (saucerfab/data/studio/index.html); "
                               "reinstall saucerfab")
        return FileResponse(page, headers={"Cache-Control": "no-cache"})

    async def session(request: Request) -> Response:
        me = _me(request)
        return _json_response({"auth": auth.required, "user": me.name if auth.required else None, "admin": me.admin})

    async def options(request: Request) -> Response:
        if not choices:
            choices.update(await run_in_threadpool(opts.option_choices))
        return _json_response({
            **choices,
            # people's words for the stage, energy and stop-reason keys the progress and results carry
            "labels": api_labels(),
            "limits": {"max_upload_bytes": max_upload_bytes, "max_pixels": pixels,
                       "max_user_upload_bytes": max_user_upload_bytes, "max_queued_per_user": max_queued_per_user},
            "samples": [{"name": n, "role": role, "url": f"/api/samples/{n}"} for n, (_, role) in samples.items()],
        })

    # ------------------------------------------------------------------ uploads

    async def upload(request: Request) -> Response:
        role = request.query_params.get("role", "")
        if role not in ROLES:
            raise StudioError(f"upload role {role[:40]!r} is unknown; give ?role= one of {', '.join(ROLES)}")
        declared = request.headers.get("content-length", "")
        if declared.isdigit() and int(declared) > max_upload_bytes:
            raise TooLarge(_too_large(int(declared)))
        mine = _uploads(request)
        used = await run_in_threadpool(mine.upload_bytes)
        if declared.isdigit():
            _check_share(used, int(declared))
        fd, tmp = mine.incoming()
        try:
            size = 0
            with os.fdopen(fd, "wb") as fh:
                async for chunk in request.stream():
                    size += len(chunk)
                    if size > max_upload_bytes:
                        raise TooLarge(_too_large(size, more=True))
                    _check_share(used, size)
                    fh.write(chunk)
            if size == 0:
                raise StudioError("the upload is empty: send the file's bytes as the request body (not a form)")
            rec = await run_in_threadpool(mine.store_upload, tmp, role, request.query_params.get("name"),
                                          max_pixels=pixels)
        finally:
            tmp.unlink(missing_ok=True)
        return _json_response(_upload_doc(rec), 201)

    def _too_large(size: int, more: bool = False) -> str:
        return (f"the file is {'over ' if more else ''}{size:,} bytes; the studio takes uploads up to "
                f"{max_upload_bytes:,} bytes. Downscale or re-compress it (a view frame is a few hundred pixels)")

    def _check_share(used: int, size: int) -> None:
        """A user's uploads together stay within ``max_user_upload_bytes`` (413 otherwise)."""
        if used + size > max_user_upload_bytes:
            raise TooLarge(f"your uploads take {used:,} bytes and this file would bring them over "
                           f"{max_user_upload_bytes:,} bytes, the most one designer may keep (--max-user-upload-mb "
                           f"{max_user_upload_bytes / 2**20:g}); choose among the pictures you uploaded before, or "
                           "ask whoever runs the studio to raise --max-user-upload-mb")

    def _upload_doc(rec: dict[str, Any]) -> dict[str, Any]:
        return {**rec, "thumb_url": f"/api/uploads/{rec['id']}/thumb.png",
                "fitted_url": f"/api/uploads/{rec['id']}/fitted.png"}

    async def sample_picture(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in samples:
            raise NotFound(f"no sample {name[:40]!r}; the samples are {', '.join(samples)}")
        return FileResponse(samples[name][0], headers={"Cache-Control": "max-age=3600"})

    async def sample_upload(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in samples:
            raise NotFound(f"no sample {name[:40]!r}; the samples are {', '.join(samples)}")
        src, role = samples[name]
        role = request.query_params.get("role", role)
        mine = _uploads(request)
        _check_share(await run_in_threadpool(mine.upload_bytes), src.stat().st_size)

        def copy() -> dict[str, Any]:
            fd, tmp = mine.incoming()
            with os.fdopen(fd, "wb") as fh:
                fh.write(src.read_bytes())
            return mine.store_upload(tmp, role, src.name, max_pixels=pixels)

        return _json_response(_upload_doc(await run_in_threadpool(copy)), 201)

    async def upload_thumb(request: Request) -> Response:
        d = _uploads(request).upload_dir(request.path_params["id"])
        # private: a user's picture is not for a shared cache (a proxy) to hand to another
        return FileResponse(d / "thumb.png", media_type="image/png",
                            headers={"Cache-Control": "private, max-age=86400"})

    async def upload_fitted(request: Request) -> Response:
        from saucerfab.imaging.fitting import FITS

        upload_id = request.path_params["id"]
        q = request.query_params
        fit = q.get("fit", FITS[0])
        if fit not in FITS:
            raise StudioError(f"fit must be one of {', '.join(FITS)}, got {fit[:20]!r}")
        size_text = q.get("size", "256")
        if not size_text.isdigit() or not FITTED_PX[0] <= int(size_text) <= FITTED_PX[1]:
            raise StudioError(f"size must be a whole number of pixels from {FITTED_PX[0]} to {FITTED_PX[1]}")
        data = await run_in_threadpool(_fitted_png, _uploads(request), upload_id, fit, q.get("background"),
                                       int(size_text), pixels)
        return Response(data, media_type="image/png", headers={"Cache-Control": "private, max-age=3600"})

    # ------------------------------------------------------------------ runs

    def _summary(rec: dict[str, Any], me: User) -> dict[str, Any]:
        d = ws.runs / rec["id"]
        return {k: rec.get(k) for k in ("id", "title", "status", "created", "error")} | {
            "thumb_url": thumb_url(rec["id"], d, rec)} | ({"owner": owner_of(rec)} if me.admin else {})

    def _full(run_id: str) -> dict[str, Any]:
        rec = ws.read_run(run_id)
        rec["owner"] = owner_of(rec)
        d = ws.run_dir(run_id)
        try:
            progress = json.loads((d / "progress.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            progress = None
        rec["progress"] = progress
        rec["thumb_url"] = thumb_url(run_id, d, rec)
        rec["results"] = design_results(run_id, d) if rec.get("status") == "done" else None
        rec["queue"] = queue.position(Job("design", run_id)) if rec.get("status") == "queued" else None
        return rec

    async def create_run(request: Request) -> Response:
        body = await _body_json(request)
        mine = _uploads(request)
        options, title = await run_in_threadpool(opts.check_options, mine, body)
        await run_in_threadpool(opts.validate_run, mine, options)
        return _json_response(await _queue_new(options, title, _me(request).name), 201)

    async def _queue_new(options: dict[str, Any], title: str, user: str) -> dict[str, Any]:
        """A new run of ``user``, queued when their share of the queue has room (else 429, and no run)."""
        async with queuing:
            queue.check_room(user)
            rec = await run_in_threadpool(ws.create_run, options, title, user)
            _submit(Job("design", rec["id"]), user)
        return await run_in_threadpool(_full, rec["id"])

    def _submit(job: Job, user: str) -> None:
        try:
            queue.submit(job, user)
        except RuntimeError as exc:  # shutting down: it stays queued and starts at the next start
            log.warning("%s", exc)

    async def list_runs(request: Request) -> Response:
        me = _me(request)
        return _json_response([_summary(r, me) for r in await run_in_threadpool(ws.list_runs)
                               if me.sees(owner_of(r))])

    async def get_run(request: Request) -> Response:
        return _json_response(await run_in_threadpool(_full, await _run(request)))

    async def cancel(request: Request) -> Response:
        run_id = await _run(request)

        def change(rec: dict[str, Any]) -> None:
            status = rec.get("status")
            if status == "queued":
                queue.discard(Job("design", run_id))
                rec.update(status="cancelled", finished=now_iso(),
                           error="cancelled before it started; resume queues it again")
            elif status == "running":
                rec["status"] = "cancelling"
            elif status != "cancelling":
                raise Conflict(f"run {run_id} is {status}; only a queued or running design can be cancelled")

        rec = await run_in_threadpool(ws.update_run, run_id, change)
        if rec["status"] == "cancelling":
            queue.stop(run_id)
        return _json_response(await run_in_threadpool(_full, run_id))

    async def resume(request: Request) -> Response:
        run_id = await _run(request)

        def change(rec: dict[str, Any]) -> None:
            status = rec.get("status")
            if status not in ("cancelled", "interrupted", "failed"):
                raise Conflict(f"run {run_id} is {status}; only a cancelled, interrupted or failed design resumes")
            rec.update(status="queued", error=None, finished=None, notes=[])

        async with queuing:  # the run's owner's share of the queue (the admin may resume another's run)
            owner = owner_of(await run_in_threadpool(ws.read_run, run_id))
            queue.check_room(owner)
            await run_in_threadpool(ws.update_run, run_id, change)
            _submit(Job("design", run_id), owner)
        return _json_response(await run_in_threadpool(_full, run_id))

    async def duplicate(request: Request) -> Response:
        run_id = await _run(request)
        changes = await _body_json(request)
        old = await run_in_threadpool(ws.read_run, run_id)
        merged = opts.merged_options(old.get("options", {}), changes)
        if "title" not in merged:
            merged["title"] = f"{old.get('title', run_id)} (copy)"
        mine = _uploads(request)  # the admin's view finds the uploads of the run it copies, whoever's they are
        options, title = await run_in_threadpool(opts.check_options, mine, merged)
        await run_in_threadpool(opts.validate_run, mine, options)
        return _json_response(await _queue_new(options, title, _me(request).name), 201)

    async def delete_run(request: Request) -> Response:
        run_id = await _run(request)
        await run_in_threadpool(ws.delete_run, run_id)
        return _json_response({"deleted": run_id})

    async def events(request: Request) -> Response:
        run_id = await _run(request)
        d = ws.run_dir(run_id)
        where = lambda: queue.position(Job("design", run_id))  # noqa: E731
        return StreamingResponse(_event_stream(ws, run_id, d, where), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    async def run_file(request: Request) -> Response:
        path = _inside(ws.run_dir(await _run(request)), request.path_params["path"])
        return FileResponse(path, media_type=SERVED_SUFFIXES[path.suffix.lower()],
                            headers={"Cache-Control": "no-cache", "X-Content-Type-Options": "nosniff"})

    async def viewer(request: Request) -> Response:
        run_id = await _run(request)
        d = ws.run_dir(run_id)
        if not (d / "design" / "design.json").is_file():
            status = ws.read_run(run_id).get("status")
            raise Conflict(f"run {run_id} has no design yet ({status}); wait until it is done")
        page = await run_in_threadpool(viewer_page, d)
        return FileResponse(page, media_type="text/html; charset=utf-8", headers={"Cache-Control": "no-cache"})

    # ------------------------------------------------------------------ exports

    async def start_export(request: Request) -> Response:
        from saucerfab.files.formats import FORMATS
        from saucerfab.model.profiles import list_profiles

        run_id = await _run(request)
        body = await _body_json(request)
        if not isinstance(body, dict):
            raise StudioError('the export options must be a JSON object, e.g. {"printer": "j55", "formats": ["3mf"]}')
        printers = await run_in_threadpool(list_profiles)
        printer = body.get("printer")
        if printer not in printers:
            raise StudioError(f"unknown printer {str(printer)[:40]!r}; the printers are {', '.join(sorted(printers))}")
        formats = body.get("formats")
        if formats is not None:
            if not isinstance(formats, list) or not formats or not all(f in FORMATS for f in formats):
                raise StudioError(f"formats must be a list of {', '.join(FORMATS)} (or null: the printer's "
                                  f"preferred format), got {str(formats)[:80]}")
            formats = list(dict.fromkeys(formats))
            taken = printers[printer].accepted_formats  # the export's rule, said now rather than by the worker
            if refused := [f for f in formats if f not in taken]:
                raise StudioError(f"{printers[printer].name} does not take {', '.join(f.upper() for f in refused)}; "
                                  f"choose among {', '.join(taken)}")
        entry = {"status": "queued", "error": None, "formats": formats, "printable": None, "files": [],
                 "zip": None, "created": now_iso()}

        def change(rec: dict[str, Any]) -> None:
            if rec.get("status") != "done":
                raise Conflict(f"run {run_id} is {rec.get('status')}; a design can be exported once it is done")
            old = rec.setdefault("exports", {}).get(printer, {})
            if old.get("status") in ("queued", "running"):
                raise Conflict(f"run {run_id} is already exporting for {printer}; wait until it is done")
            if (lit_entry(rec, printer) or {}).get("status") in LIT_ACTIVE:  # it reads the folder an export replaces
                raise Conflict(f"the export for {printer} is being rendered under the room light; wait until it is "
                               "done, then export again")
            rec["exports"][printer] = dict(entry)

        rec = await run_in_threadpool(ws.update_run, run_id, change)
        _submit(Job("export", run_id, printer), owner_of(rec))
        return _json_response(export_details(run_id, ws.run_dir(run_id), printer, entry), 202)

    async def start_lit(request: Request) -> Response:
        """An export seen under the room light (:mod:`saucerfab.studio.lit`): a queued ``lit`` job; 202."""
        run_id, printer = await _run(request), request.path_params["printer"]
        rec = await run_in_threadpool(queue_lit, ws, run_id, printer)
        _submit(Job("lit", run_id, printer), owner_of(rec))
        return _json_response(await run_in_threadpool(export_details, run_id, ws.run_dir(run_id), printer,
                                                      rec["exports"][printer]), 202)

    def _export_entry(run_id: str, printer: str) -> dict[str, Any]:
        entry = ws.read_run(run_id).get("exports", {}).get(printer)
        if not isinstance(entry, dict):
            raise NotFound(f"run {run_id} has no export for {printer[:40]!r}; start one with POST .../exports")
        return entry

    async def get_export(request: Request) -> Response:
        run_id, printer = await _run(request), request.path_params["printer"]
        d = ws.run_dir(run_id)
        entry = await run_in_threadpool(_export_entry, run_id, printer)
        return _json_response(await run_in_threadpool(export_details, run_id, d, printer, entry))

    async def export_zip(request: Request) -> Response:
        run_id, printer = await _run(request), request.path_params["printer"]
        d = ws.run_dir(run_id)
        entry = await run_in_threadpool(_export_entry, run_id, printer)
        path = d / "exports" / f"{printer}.zip"
        if entry.get("status") != "done" or not path.is_file():
            raise Conflict(f"the export for {printer} is {entry.get('status')}; its zip is there once it is done")
        return FileResponse(path, media_type="application/zip", filename=f"saucerfab-{run_id}-{printer}.zip")

    # ------------------------------------------------------------------ errors and lifespan

    async def studio_error(request: Request, exc: Exception) -> Response:
        return _error(getattr(exc, "status", 400), ws.scrub(str(exc)))

    async def client_gone(request: Request, exc: Exception) -> Response:
        # the client left mid-request (a tab closed during an upload): nothing was kept, nobody reads this
        return _error(400, "the request was cut off before its end; send it again")

    async def http_error(request: Request, exc: Exception) -> Response:
        status = getattr(exc, "status_code", 500)
        text = "no such page or API route" if status == 404 else str(getattr(exc, "detail", exc))
        return _error(status, text)

    async def server_error(request: Request, exc: Exception) -> Response:
        log.error("internal error on %s %s", request.method, request.url.path, exc_info=exc)
        if isinstance(exc, OSError):  # a full disk, a folder made read-only: the machine's, not the request's
            return _error(500, f"internal error: the studio cannot read or write its workspace "
                               f"({exc.strerror or type(exc).__name__}); free some space or fix its permissions")
        return _error(500, f"internal error ({type(exc).__name__}); the details are in the studio's log")

    @asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        designs, exports = await run_in_threadpool(ws.startup_scan)
        owners = {r["id"]: owner_of(r) for r in await run_in_threadpool(ws.list_runs)}
        queue.start()
        for run_id in designs:  # queued again, past the limit of a user's share: they were taken before
            _submit(Job("design", run_id), owners.get(run_id, SHARED_USER))
        for run_id, printer in exports:
            _submit(Job("export", run_id, printer), owners.get(run_id, SHARED_USER))
        for run_id, printer in await run_in_threadpool(ws.queued_lits):  # exports asked for under the room light
            _submit(Job("lit", run_id, printer), owners.get(run_id, SHARED_USER))
        try:
            yield
        finally:
            await run_in_threadpool(queue.shutdown)

    routes = [
        Route("/", index),
        Mount("/static", StaticFiles(directory=STATIC, check_dir=False), name="static"),
        *(login_routes(auth, cookie) if auth.required else []),
        Route("/api/session", session),
        Route("/api/options", options),
        Route("/api/uploads", upload, methods=["POST"]),
        Route("/api/samples/{name}", sample_picture, methods=["GET"]),
        Route("/api/samples/{name}", sample_upload, methods=["POST"]),
        Route("/api/uploads/{id}/thumb.png", upload_thumb),
        Route("/api/uploads/{id}/fitted.png", upload_fitted),
        Route("/api/runs", list_runs, methods=["GET"]),
        Route("/api/runs", create_run, methods=["POST"]),
        Route("/api/runs/{id}", get_run, methods=["GET"]),
        Route("/api/runs/{id}", delete_run, methods=["DELETE"]),
        Route("/api/runs/{id}/events", events),
        Route("/api/runs/{id}/cancel", cancel, methods=["POST"]),
        Route("/api/runs/{id}/resume", resume, methods=["POST"]),
        Route("/api/runs/{id}/duplicate", duplicate, methods=["POST"]),
        Route("/api/runs/{id}/files/{path:path}", run_file),
        Route("/api/runs/{id}/viewer", viewer),
        Route("/api/runs/{id}/exports", start_export, methods=["POST"]),
        Route("/api/runs/{id}/exports/{printer}.zip", export_zip),
        Route("/api/runs/{id}/exports/{printer}", get_export),
        Route("/api/runs/{id}/exports/{printer}/lit", start_lit, methods=["POST"]),
    ]
    app = Starlette(
        routes=routes,
        # the guard first: a rebound name or another site's request is refused before anyone signs in
        middleware=[Middleware(HostOriginGuard, allowed_hosts=allowed_hosts),
                    Middleware(SignIn, auth=auth, cookie=cookie)],
        lifespan=lifespan,
        exception_handlers={StudioError: studio_error, SaucerfabError: studio_error, HTTPException: http_error,
                            ClientDisconnect: client_gone, Exception: server_error},
    )
    app.state.workspace = ws
    app.state.queue = queue
    app.state.auth = auth
    return app


def _inside(run_dir: Path, rel: str) -> Path:
    """The file ``rel`` of a run folder, when it is a served kind and really inside; else NotFound.

    No hidden part (the checkpoint, the lock), no ``..``, no absolute path,
    no link out of the folder: the path is resolved and must stay under it.
    """
    parts = rel.replace("\\", "/").split("/")
    bad = not rel or "\x00" in rel or any(p in ("", ".", "..") or p.startswith(".") for p in parts)
    if bad or Path(rel).suffix.lower() not in SERVED_SUFFIXES:
        raise NotFound(f"no file {rel[:80]!r} in this run")
    root = run_dir.resolve()
    path = (root / rel).resolve()
    if not path.is_relative_to(root) or not path.is_file():
        raise NotFound(f"no file {rel[:80]!r} in this run")
    return path


def _fitted_png(ws: Workspace, upload_id: str, fit: str, background: str | None, size: int, max_pixels: int) -> bytes:
    """An uploaded picture fitted into its square frame as the design fits it, as PNG bytes."""
    import numpy as np

    from saucerfab.files.imageio import png_bytes
    from saucerfab.imaging.fitting import fit_square
    from saucerfab.imaging.images import estimate_background, flatten_alpha, load_image, parse_colour

    rec = ws.upload_record(upload_id)
    if rec.get("kind") != "image":
        raise StudioError(f"upload {upload_id} is a {rec.get('kind')}; only pictures are fitted into frames")
    img = load_image(ws.upload_path(upload_id), max_pixels=max_pixels)
    bg = estimate_background(img.rgb, img.alpha) if not background else parse_colour(background)
    rgb, alpha, _ = fit_square(img, size, background=bg, fit=fit)
    if alpha is not None:
        rgb = flatten_alpha(rgb, alpha, bg)
    return png_bytes(np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8))


def _event(kind: str, doc: Any) -> bytes:
    return f"event: {kind}\ndata: {json.dumps(doc, default=str)}\n\n".encode()


async def _event_stream(ws: Workspace, run_id: str, folder: Path,
                        where: Any = lambda: None) -> AsyncIterator[bytes]:
    """Server-Sent Events of one run: ``progress`` when progress.json changes, ``status`` when the record's
    status (or error) changes, or its place in the queue (``where()``, the record's ``queue``); ends after a
    final status.

    A client that goes away cancels this generator at its next ``yield`` or
    sleep: nothing else is held, so there is nothing to clean up.
    """
    last_progress: bytes | None = None
    last_state: tuple[Any, Any, str] | None = None
    beat = time.monotonic()
    while True:
        try:
            rec = ws.read_run(run_id)
        except NotFound:
            yield _event("status", {"id": run_id, "status": "deleted", "error": "the run was deleted"})
            return
        rec["queue"] = where() if rec.get("status") == "queued" else None
        state = (rec.get("status"), rec.get("error"), json.dumps(rec["queue"]))
        if last_state is None:  # the first event says where the run stands
            last_state = state
            yield _event("status", rec)
        try:
            raw = (folder / "progress.json").read_bytes()
        except OSError:
            raw = None
        sent_progress = False
        if raw is not None and raw != last_progress:
            last_progress = raw
            sent_progress = True
            try:
                yield _event("progress", json.loads(raw))
            except ValueError:
                pass
            beat = time.monotonic()
        final = rec.get("status") in FINAL
        if state != last_state or (final and sent_progress):
            # a final status is always the stream's last event, after the last progress
            last_state = state
            yield _event("status", rec)
            beat = time.monotonic()
        if final:
            return
        if time.monotonic() - beat > KEEPALIVE_S:
            yield b": keep-alive\n\n"
            beat = time.monotonic()
        await anyio.sleep(EVENT_POLL_S)
