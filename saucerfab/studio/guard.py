"""Who may talk to the studio: the Host and Origin checks of a local web application.

The studio has no login: it trusts whoever can reach it, which on the
default loopback address is this machine's user. Two browser attacks reach
a loopback server from a web page the user merely visits, and this
middleware refuses both before any route runs:

* **DNS rebinding**: a page on ``evil.example`` re-points its own name at
  127.0.0.1 and then talks to the studio as same-origin. Its requests carry
  ``Host: evil.example``; on loopback only the loopback names are accepted
  (:data:`LOOPBACK_NAMES`), so they get 421.
* **Cross-site requests** (CSRF): a page anywhere can make the browser POST
  to ``http://127.0.0.1:8000/api/...`` (a "simple" request needs no
  preflight). Browsers send ``Origin`` with every POST, PUT, PATCH and
  DELETE; one whose host and port differ from the request's ``Host`` gets 403.
  A request with no ``Origin`` (curl, scripts, the test client) is not a
  browser's cross-site request and passes.

With ``--host`` set to a network address the user has chosen to share the
studio; any ``Host`` is then accepted (the machine's names are not known
here), and the Origin check still holds.
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, MutableMapping, Sequence
from typing import Any
from urllib.parse import urlsplit

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

#: the Host names a loopback studio answers to
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
#: methods that change something: these must not come from another site
UNSAFE_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})


def _host_name(host: str) -> str:
    """``host[:port]`` or ``[v6]:port`` -> the name without port or brackets, lower case."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:].split("]", 1)[0]
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


class HostOriginGuard:
    """ASGI middleware: refuse requests whose ``Host`` is not allowed (421) or whose ``Origin`` is foreign (403).

    Args:
        app: the application behind it.
        allowed_hosts: the host names accepted in ``Host`` (without port), or
            None to accept any (a studio shared on the network).
    """

    def __init__(self, app: ASGIApp, allowed_hosts: Sequence[str] | None = LOOPBACK_NAMES) -> None:
        self.app = app
        self.allowed = None if allowed_hosts is None else frozenset(h.lower() for h in allowed_hosts)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":  # lifespan (and websockets, which the studio does not serve)
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        host = headers.get("host", "")
        if self.allowed is not None and _host_name(host) not in self.allowed:
            await _refuse(send, 421, f"this studio answers to {', '.join(sorted(self.allowed))} only, not "
                                     f"{host[:80]!r}; open it at the address it printed when it started")
            return
        origin = headers.get("origin")
        if scope.get("method", "GET").upper() in UNSAFE_METHODS and origin is not None:
            if origin == "null" or urlsplit(origin).netloc.lower() != host.lower():
                await _refuse(send, 403, f"a request from another site ({origin[:80]}) was refused: only the "
                                         "studio's own page may change designs")
                return
        await self.app(scope, receive, send)


async def _refuse(send: Send, status: int, message: str) -> None:
    body = json.dumps({"error": message}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})
