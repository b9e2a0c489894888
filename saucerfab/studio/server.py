"""Serving the studio: its sign-in, the workspace's lock, uvicorn, the banner, ``--open``.

:func:`serve` is what ``saucerfab studio`` runs. It asks for a token
(:mod:`saucerfab.studio.auth`): a random one printed in the banner's URL
unless one is given, and on a network address always, unless ``--no-auth``.
One server per workspace:
it holds an ``flock`` on ``WORKSPACE/.lock`` while it runs (freed by the
kernel however the process ends), so a second server on the same folder
stops at once with a clear message instead of two job queues fighting over
the same runs.
"""

from __future__ import annotations

import ipaddress
import os
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Any
from urllib.parse import quote

from saucerfab.errors import ConfigError
from saucerfab.files.fileio import exclusive_lock
from saucerfab.studio.jobs import DEFAULT_JOBS, DEFAULT_MAX_QUEUED_PER_USER
from saucerfab.studio.workspace import MAX_UPLOAD_BYTES, MAX_USER_UPLOAD_BYTES, Workspace

#: the address served by default: this machine only
DEFAULT_HOST = "127.0.0.1"
#: the port served by default
DEFAULT_PORT = 8000
#: the workspace used when none is given
DEFAULT_WORKSPACE = Path("~/saucerfab-studio")
#: seconds uvicorn waits for open connections (event streams) when it stops
SHUTDOWN_WAIT_S = 3


def is_loopback(host: str) -> bool:
    """Whether ``host`` is an address of this machine only (``127.0.0.1``, ``::1``, ``localhost``)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def url_of(host: str, port: int) -> str:
    """The page's URL for a browser (a wildcard address shown as this machine's loopback)."""
    shown = {"0.0.0.0": "127.0.0.1", "::": "[::1]"}.get(host, f"[{host}]" if ":" in host else host)
    return f"http://{shown}:{port}/"


def _check_port(host: str, port: int) -> None:
    """Refuse a port another program holds, before uvicorn tries (its own message is a log line)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            raise ConfigError(
                f"cannot serve on {host}:{port}: {exc.strerror or exc}. Another program (or another studio) uses "
                f"it: give another --port, e.g. --port {port + 1}"
            ) from None


def server_config(app: Any, host: str, port: int, log_level: str = "warning") -> Any:
    """The ``uvicorn.Config`` the studio serves ``app`` with: its logs never show a token
    (:func:`saucerfab.studio.auth.uvicorn_log_config`; the access log would print ``?token=``)."""
    import uvicorn

    from saucerfab.studio.auth import uvicorn_log_config

    return uvicorn.Config(app, host=host, port=port, log_level=log_level, lifespan="on",
                          timeout_graceful_shutdown=SHUTDOWN_WAIT_S, log_config=uvicorn_log_config())


def serve(
    workspace: str | Path = DEFAULT_WORKSPACE,
    *,
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    jobs: int = DEFAULT_JOBS,
    max_upload_bytes: int = MAX_UPLOAD_BYTES,
    open_browser: bool = False,
    token: str | None = None,
    token_file: str | Path | None = None,
    no_auth: bool = False,
    max_queued_per_user: int = DEFAULT_MAX_QUEUED_PER_USER,
    max_user_upload_bytes: int = MAX_USER_UPLOAD_BYTES,
    scheduler: str | None = None,
) -> int:
    """Serve the studio until Ctrl-C; returns the exit code.

    Args:
        token, token_file: the sign-in token, or a file of one token or of
            ``USER:TOKEN`` lines (at most one of them and ``$SAUCERFAB_STUDIO_TOKEN``);
            none: a random token, printed in the banner's URL.
        no_auth: no sign-in (anyone who can reach the studio uses it).
        max_queued_per_user: designs one user may have waiting (0: no limit).
        max_user_upload_bytes: bytes of uploads one user may keep.
        scheduler: ``tcp://HOST:PORT`` of a Dask scheduler to run the jobs on
            (:mod:`saucerfab.studio.cluster`; the workspace must be on a filesystem its workers see).

    Raises:
        ConfigError: a bad workspace, another studio on it, a port in use, bad
            numbers, contradictory or weak tokens, a network host without a token.
    """
    from saucerfab.studio.auth import resolve_auth

    if not 0 <= port <= 65535:
        raise ConfigError(f"--port must be 0 to 65535, got {port}")
    if jobs < 1:
        raise ConfigError(f"--jobs must be at least 1, got {jobs}")
    if max_upload_bytes < 1:
        raise ConfigError(f"--max-upload-mb must be positive, got {max_upload_bytes / 2**20:g}")
    if max_user_upload_bytes < 1:
        raise ConfigError(f"--max-user-upload-mb must be positive, got {max_user_upload_bytes / 2**20:g}")
    if max_queued_per_user < 0:
        raise ConfigError(f"--max-queued-per-user must be 0 (no limit) or more, got {max_queued_per_user}")
    auth, made = resolve_auth(token, token_file, no_auth, host=host, loopback=is_loopback(host), env=os.environ)
    ws = Workspace(workspace)
    busy = lambda: ConfigError(  # noqa: E731
        f"another saucerfab studio is already serving the workspace {str(ws.root)!r}; open its page, or give "
        "another --workspace"
    )
    with exclusive_lock(ws.root / ".lock", busy):
        _check_port(host, port)
        cluster = None
        if scheduler:
            from saucerfab.studio.cluster import DaskCluster

            cluster = DaskCluster(scheduler, ws.root)  # refuses a cluster whose workers do not see the workspace
        try:
            return _serve(ws, host, port, jobs, max_upload_bytes, max_queued_per_user, max_user_upload_bytes,
                          cluster, auth, made, open_browser)
        finally:
            if cluster is not None:
                cluster.close()


def _serve(ws: Workspace, host: str, port: int, jobs: int, max_upload_bytes: int, max_queued_per_user: int,
           max_user_upload_bytes: int, cluster: Any, auth: Any, made: str | None, open_browser: bool) -> int:
    """Build the app, print the banner, run uvicorn until Ctrl-C (the workspace is locked by the caller)."""
    import uvicorn

    from saucerfab.studio.app import create_app
    from saucerfab.studio.guard import LOOPBACK_NAMES

    app = create_app(ws.root, jobs=jobs, max_upload_bytes=max_upload_bytes,
                     allowed_hosts=LOOPBACK_NAMES if is_loopback(host) else None, auth=auth,
                     max_queued_per_user=max_queued_per_user, max_user_upload_bytes=max_user_upload_bytes,
                     cluster=cluster)
    if cluster is not None:
        print(f"saucerfab studio: designs and exports run on the Dask cluster at {cluster.address} "
              f"({cluster.slots()} at once)", flush=True)
    url = url_of(host, port)
    if made is not None:  # printed once, here: the URL signs the browser in (and the token leaves it)
        url += "?token=" + quote(made, safe="")
    print(f"saucerfab studio: {url}  (workspace {ws.root}; Ctrl-C stops it, running designs are kept "
          "and resume later)", flush=True)
    if auth.required and made is None:  # a given token is not printed: a service's output goes to its log
        who = "each user with their own token from" if len(auth.tokens or {}) > 1 else "with the token of"
        print(f"saucerfab studio: sign in {who} {auth.source}", flush=True)
    if not auth.required and not is_loopback(host):
        print(f"saucerfab studio: warning: serving on {host} with --no-auth: anyone on the network who can "
              "reach this machine can use the studio and its files; there is no authentication",
              file=sys.stderr, flush=True)
    server = uvicorn.Server(server_config(app, host, port))
    if open_browser:
        threading.Thread(target=_open_when_up, args=(server, url, ws.root), daemon=True).start()
    server.run()
    return 0 if server.started else 2


#: the page ``--open`` hands the browser when the URL holds the token (in the workspace, the user's alone)
OPEN_PAGE = ".open.html"


def browser_target(url: str, folder: Path) -> str:
    """What ``--open`` gives the browser: ``url``, or, when it holds the token, a local page that goes there.

    A URL on the browser's command line is visible to every user of the machine in its process list;
    as Jupyter does, the token goes into a file only this user may read (``folder/.open.html``, mode
    0600) whose page redirects to ``url``, and the browser is given that file's address.
    """
    import html

    if "token=" not in url:
        return url
    page = (f'<!DOCTYPE html><html><head><meta charset="utf-8"><meta http-equiv="refresh" content="0;url='
            f'{html.escape(url, quote=True)}"><title>saucerfab studio</title></head><body><p><a href="'
            f'{html.escape(url, quote=True)}">Open the studio</a></p></body></html>\n')
    path = folder / OPEN_PAGE
    tmp = folder / f".{OPEN_PAGE}.{os.getpid()}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)  # never readable by others, even briefly
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(page)
    os.replace(tmp, path)
    return path.resolve().as_uri()


def _open_when_up(server: object, url: str, folder: Path) -> None:
    """Open the studio in the user's browser once uvicorn is listening (the token kept off the command line)."""
    import webbrowser

    for _ in range(300):
        if getattr(server, "started", False):
            webbrowser.open(browser_target(url, folder))
            return
        time.sleep(0.1)
