"""Serving the studio: the workspace's lock, uvicorn, the banner, ``--open``.

:func:`serve` is what ``saucerfab studio`` runs. One server per workspace:
it holds an ``flock`` on ``WORKSPACE/.lock`` while it runs (freed by the
kernel however the process ends), so a second server on the same folder
stops at once with a clear message instead of two job queues fighting over
the same runs.
"""

from __future__ import annotations

import ipaddress
import socket
import sys
import threading
import time
from pathlib import Path

from saucerfab.errors import ConfigError
from saucerfab.files.fileio import exclusive_lock
from saucerfab.studio.jobs import DEFAULT_JOBS
from saucerfab.studio.workspace import MAX_UPLOAD_BYTES, Workspace

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


def serve(
    workspace: str | Path = DEFAULT_WORKSPACE,
    *,
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    jobs: int = DEFAULT_JOBS,
    max_upload_bytes: int = MAX_UPLOAD_BYTES,
    open_browser: bool = False,
) -> int:
    """Serve the studio until Ctrl-C; returns the exit code.

    Raises:
        ConfigError: a bad workspace, another studio on it, a port in use, bad numbers.
    """
    import uvicorn

    from saucerfab.studio.app import create_app
    from saucerfab.studio.guard import LOOPBACK_NAMES

    if not 0 <= port <= 65535:
        raise ConfigError(f"--port must be 0 to 65535, got {port}")
    if jobs < 1:
        raise ConfigError(f"--jobs must be at least 1, got {jobs}")
    if max_upload_bytes < 1:
        raise ConfigError(f"--max-upload-mb must be positive, got {max_upload_bytes / 2**20:g}")
    ws = Workspace(workspace)
    busy = lambda: ConfigError(  # noqa: E731
        f"another saucerfab studio is already serving the workspace {str(ws.root)!r}; open its page, or give "
        "another --workspace"
    )
    with exclusive_lock(ws.root / ".lock", busy):
        _check_port(host, port)
        app = create_app(ws.root, jobs=jobs, max_upload_bytes=max_upload_bytes,
                         allowed_hosts=LOOPBACK_NAMES if is_loopback(host) else None)
        url = url_of(host, port)
        print(f"saucerfab studio: {url}  (workspace {ws.root}; Ctrl-C stops it, running designs are kept "
              "and resume later)", flush=True)
        if not is_loopback(host):
            print(f"saucerfab studio: warning: serving on {host}: anyone on the network who can reach this "
                  "machine can use the studio and its files; there is no authentication", file=sys.stderr,
                  flush=True)
        config = uvicorn.Config(app, host=host, port=port, log_level="warning", lifespan="on",
                                timeout_graceful_shutdown=SHUTDOWN_WAIT_S)
        server = uvicorn.Server(config)
        if open_browser:
            threading.Thread(target=_open_when_up, args=(server, url), daemon=True).start()
        server.run()
        return 0 if server.started else 2


def _open_when_up(server: object, url: str) -> None:
    """Open ``url`` in the user's browser once uvicorn is listening."""
    import webbrowser

    for _ in range(300):
        if getattr(server, "started", False):
            webbrowser.open(url)
            return
        time.sleep(0.1)
