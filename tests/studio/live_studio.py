"""A real ``saucerfab studio`` server in a subprocess, for the browser test and the README screenshot script.

Started on a free loopback port with its own workspace; ``stop_studio``
sends Ctrl-C (the server stops its workers) and kills the process group
if it does not end. With ``sign_in`` the server makes its own token, as
``saucerfab studio`` does by default, and :func:`printed_url` reads the URL
with it from the server's output; without, it runs with ``--no-auth``
(the screenshot script opens the bare page).
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: seconds the server may take to answer its first request (it imports the library)
STARTUP_S = 60


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def http_get(url: str, timeout: float = 5, headers: dict[str, str] | None = None) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {}), timeout=timeout) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def start_studio(workspace: Path, port: int, log: Path, *, sign_in: bool = False) -> subprocess.Popen[bytes]:
    """``saucerfab studio`` in a subprocess, once it answers ``GET /api/options`` (a 401 counts: it asks for
    its token)."""
    env = {k: v for k, v in os.environ.items() if k != "SAUCERFAB_STUDIO_TOKEN"} | {"PYTHONUNBUFFERED": "1"}
    auth = [] if sign_in else ["--no-auth"]
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "saucerfab", "studio", "--workspace", str(workspace), "--port", str(port), *auth],
            cwd=ROOT,
            stdout=out,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )
    deadline = time.monotonic() + STARTUP_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError(f"saucerfab studio exited with {proc.returncode}:\n{_tail(log)}")
        try:
            if http_get(f"http://127.0.0.1:{port}/api/options", timeout=2)[0] in (200, 401):
                return proc
        except OSError:
            pass
        time.sleep(0.2)
    stop_studio(proc)
    raise AssertionError(f"saucerfab studio did not answer in {STARTUP_S} s:\n{_tail(log)}")


def printed_url(log: Path) -> str:
    """The URL with the token that the server printed at start (``http://127.0.0.1:PORT/?token=...``)."""
    found = re.search(r"saucerfab studio: (http://\S+\?token=\S+)", log.read_text(errors="replace"))
    if not found:
        raise AssertionError(f"the studio printed no URL with a token:\n{_tail(log)}")
    return found.group(1)


def _tail(log: Path) -> str:
    return log.read_text(errors="replace")[-3000:]


def stop_studio(proc: subprocess.Popen[bytes]) -> None:
    """Ctrl-C the server (it stops its workers), then make sure."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5)


