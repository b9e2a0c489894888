"""Who may use the studio: tokens, users, the session cookie and the sign-in page (issue 39).

As Jupyter does it: the studio has a token (a random one made at start and
printed in its URL, or one given with ``--token``, ``$SAUCERFAB_STUDIO_TOKEN``
or ``--token-file``), and every route asks for it
(:class:`SignIn`, an ASGI middleware behind the Host/Origin guard):

* ``?token=TOKEN`` in a browser's address: the answer is a redirect to the
  same address without the token (so it stays in neither the address bar
  nor the history) that sets the session cookie;
* ``Authorization: token TOKEN`` (or ``Bearer TOKEN``): scripts;
* the session cookie: ``USER.ISSUED.MAC``, HttpOnly, SameSite=Strict, where MAC
  is an HMAC-SHA256 keyed with the user's token over the user and the time it
  was issued. The token is never in it; it holds for :data:`SESSION_MAX_AGE_S`,
  across restarts, and no longer once that user's token changes.

Without any, the page (``GET /``) is the sign-in form (``saucerfab/data/studio/signin.html``,
self-contained: the static files need the token too) and everything else a
401 ``{"error": ...}`` that names the fix. Tokens are compared with
:func:`hmac.compare_digest`; :class:`RedactTokens` keeps them out of uvicorn's logs.

A token file holds one token (the studio's one shared user), or lines
``USER:TOKEN``, one per designer: each sees only their own designs and
uploads, and the user named :data:`~saucerfab.studio.workspace.SHARED_USER`
sees all of them.
"""

from __future__ import annotations

import hashlib
import hmac
import html
import json
import logging
import re
import secrets
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, quote, urlencode

from saucerfab.errors import ConfigError
from saucerfab.studio.guard import ASGIApp, Receive, Scope, Send
from saucerfab.studio.workspace import SHARED_USER, USER_RE

#: the environment variable a service gives the token in
TOKEN_ENV = "SAUCERFAB_STUDIO_TOKEN"
#: the shortest token accepted, characters (a made one has 43)
MIN_TOKEN_CHARS = 16
#: random bytes of a made token (secrets.token_urlsafe: 43 characters)
TOKEN_BYTES = 32
#: the largest token file read, bytes, and the most users in it
MAX_TOKEN_FILE_BYTES = 64 << 10
MAX_USERS = 1000
#: how long a session cookie holds, seconds (30 days)
SESSION_MAX_AGE_S = 30 * 86400
#: the sign-in form and sign-out, the two routes that need no token
LOGIN_PATH = "/login"
LOGOUT_PATH = "/logout"
#: the ASGI scope key the signed-in :class:`User` is kept under for the routes
USER_KEY = "saucerfab.studio.user"
#: the largest sign-in form body, bytes
MAX_FORM_BYTES = 4096
#: the sign-in page's policy: it is self-contained (nothing loads from anywhere) and its form posts here only
PAGE_POLICY = ("default-src 'none'; style-src 'unsafe-inline'; img-src data:; form-action 'self'; "
               "frame-ancestors 'none'")
#: the sign-in page
SIGNIN_PAGE = Path(__file__).resolve().parents[1] / "data" / "studio" / "signin.html"

_MAKE_ONE = "python -c 'import secrets; print(secrets.token_urlsafe(32))' makes one"
_FIX = ("open the URL the studio printed when it started (http://HOST:PORT/?token=...), or ask whoever runs it "
        "for your token; scripts send the header 'Authorization: token TOKEN'")
#: what the sign-in page says of a token that is not the studio's
_WRONG_IN_FORM = ("That is not this studio's token. Check it (the part after ?token= in the address the studio "
                  "printed), or ask whoever runs the studio for yours.")
_WRONG_IN_URL = ("The token in this address is not this studio's (a studio makes a new one each time it starts, "
                 "unless it is given one): paste the right one below.")
_SESSION_TAG = b"saucerfab.studio.session/1"


@dataclass(frozen=True)
class User:
    """A signed-in user; ``admin`` (the user named :data:`SHARED_USER`) sees every user's designs."""

    name: str
    admin: bool

    def sees(self, owner: str) -> bool:
        """Whether this user may see (and change) a design or upload of ``owner``."""
        return self.admin or owner == self.name


def user_named(name: str) -> User:
    """The :class:`User` of a name (the shared user is the admin)."""
    return User(name, name == SHARED_USER)


class Auth:
    """The studio's users and their tokens, or no sign-in at all.

    Args:
        tokens: user name -> token; None: no sign-in (``--no-auth``), every
            request is the shared user's.
        source: where the tokens came from, for messages ("--token-file team.txt").
    """

    def __init__(self, tokens: Mapping[str, str] | None, source: str = "") -> None:
        self.tokens = None if tokens is None else dict(tokens)
        self.source = source

    @classmethod
    def shared(cls, token: str, source: str = "") -> Auth:
        """One token for the one shared user (who is the admin)."""
        return cls({SHARED_USER: token}, source)

    @property
    def required(self) -> bool:
        """Whether a request must sign in."""
        return self.tokens is not None

    def check_token(self, token: str) -> User | None:
        """The user whose token ``token`` is, or None; every token is compared in constant time."""
        found = None
        for name, known in (self.tokens or {}).items():
            if hmac.compare_digest(token.encode(), known.encode()):
                found = name  # no early exit: the time taken does not say which user matched
        return None if found is None else user_named(found)

    def _mac(self, name: str, issued: int) -> str:
        key = (self.tokens or {})[name].encode()
        signed = b"\0".join([_SESSION_TAG, name.encode(), str(issued).encode()])
        return hmac.new(key, signed, hashlib.sha256).hexdigest()

    def session_value(self, user: User, now: float | None = None) -> str:
        """The session cookie's value for ``user`` (who must hold a token)."""
        issued = int(time.time() if now is None else now)
        return f"{user.name}.{issued}.{self._mac(user.name, issued)}"

    def session_user(self, value: str, now: float | None = None) -> User | None:
        """The user of a session cookie's value, or None when it is malformed, forged, expired or revoked."""
        parts = value.rsplit(".", 2)
        if self.tokens is None or len(parts) != 3 or parts[0] not in self.tokens or not parts[1].isdigit():
            return None
        name, issued_text, mac = parts
        issued = int(issued_text)
        age = (time.time() if now is None else now) - issued
        if not -60 <= age <= SESSION_MAX_AGE_S:  # a minute's grace for a clock stepped back
            return None
        return user_named(name) if hmac.compare_digest(mac, self._mac(name, issued)) else None


# ---------------------------------------------------------------------------------------------- where tokens come from


def _check_token(token: str, where: str) -> str:
    """``token`` if it is strong enough and fits in a URL and a header; else ConfigError naming the rule."""
    if len(token) < MIN_TOKEN_CHARS:
        raise ConfigError(f"the token {where} is {len(token)} characters; a token must be at least "
                          f"{MIN_TOKEN_CHARS} random characters ({_MAKE_ONE})")
    if not all("!" <= c <= "~" for c in token):
        raise ConfigError(f"the token {where} holds a space or a character outside printable ASCII; a token is "
                          f"letters, digits and punctuation ({_MAKE_ONE})")
    return token


def read_token_file(path: str | Path) -> Auth:
    """The users of a token file: one token (the shared user's), or lines ``USER:TOKEN``.

    Blank lines and lines starting with ``#`` are skipped. A file of one line
    without a colon is the one shared token; otherwise every line is
    ``USER:TOKEN`` (split at the first colon) with a user name of letters,
    digits, ``.``, ``_`` and ``-``.

    Raises:
        ConfigError: a missing, large or unreadable file, a bad line, a weak,
            repeated or missing token, a user named twice.
    """
    p = Path(path).expanduser()
    where = f"--token-file {str(p)!r}"
    try:
        with p.open("rb") as fh:
            data = fh.read(MAX_TOKEN_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"cannot read {where}: {exc.strerror or exc}; give a file of tokens") from None
    if len(data) > MAX_TOKEN_FILE_BYTES:
        raise ConfigError(f"{where} is over {MAX_TOKEN_FILE_BYTES:,} bytes; a token file holds one token or "
                          f"up to {MAX_USERS} lines USER:TOKEN")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ConfigError(f"{where} is not UTF-8 text; a token file holds one token or lines USER:TOKEN") from None
    lines = [(n, s.strip()) for n, s in enumerate(text.splitlines(), 1) if s.strip() and not s.strip().startswith("#")]
    if not lines:
        raise ConfigError(f"{where} holds no token; write one token, or lines USER:TOKEN ({_MAKE_ONE})")
    if len(lines) == 1 and ":" not in lines[0][1]:
        return Auth.shared(_check_token(lines[0][1], f"in {where}"), where)
    if len(lines) > MAX_USERS:
        raise ConfigError(f"{where} has {len(lines)} users; the studio takes up to {MAX_USERS}")
    users: dict[str, str] = {}
    for n, line in lines:
        name, colon, token = line.partition(":")
        name = name.strip()
        if not colon:
            raise ConfigError(f"{where} line {n} has no user: in a file of several tokens every line is USER:TOKEN")
        if not USER_RE.match(name):
            raise ConfigError(f"{where} line {n}: user name {name[:40]!r} is not letters, digits, '.', '_' and "
                              "'-' (starting with a letter or digit, at most 64)")
        if name.lower() in {u.lower() for u in users}:
            raise ConfigError(f"{where} line {n} names user {name!r} again; give each user one line")
        users[name] = _check_token(token.strip(), f"of user {name!r} in {where} line {n}")
    if len(set(users.values())) < len(users):
        raise ConfigError(f"{where} gives two users the same token; each user needs their own ({_MAKE_ONE})")
    return Auth(users, where)


def resolve_auth(token: str | None, token_file: str | Path | None, no_auth: bool, *, host: str, loopback: bool,
                 env: Mapping[str, str]) -> tuple[Auth, str | None]:
    """The studio's sign-in from its options: (auth, the token made now, or None when one was given or none is asked).

    At most one token source (``--token``, ``$SAUCERFAB_STUDIO_TOKEN``,
    ``--token-file``); none on loopback makes a random token, none on a
    network address is refused unless ``--no-auth`` says so, and ``--no-auth``
    with a token is a contradiction.

    Raises:
        ConfigError: two sources, ``--no-auth`` with a source, a network host without one, a bad token.
    """
    given = [(name, value) for name, value in (("--token", token), (f"${TOKEN_ENV}", env.get(TOKEN_ENV) or None),
                                               ("--token-file", token_file)) if value is not None]
    if no_auth and given:
        unset = f" (unset ${TOKEN_ENV})" if given[0][0] == f"${TOKEN_ENV}" else ""
        raise ConfigError(f"--no-auth and {given[0][0]} contradict each other: give the token to ask for it, or "
                          f"--no-auth alone{unset} to let in anyone who can reach the studio")
    if len(given) > 1:
        raise ConfigError(f"the token is given twice ({given[0][0]} and {given[1][0]}); give it one way")
    if no_auth:
        return Auth(None, "--no-auth"), None
    if not given:
        if not loopback:
            raise ConfigError(f"--host {host} serves the studio to the network, so it needs a token: give "
                              f"--token-file FILE (one token, or lines USER:TOKEN), ${TOKEN_ENV} or --token; or "
                              "--no-auth to let in anyone who can reach it")
        made = secrets.token_urlsafe(TOKEN_BYTES)
        return Auth.shared(made, "the token made at start"), made
    name, value = given[0]
    if name == "--token-file":
        return read_token_file(value), None
    return Auth.shared(_check_token(str(value), f"given with {name}"), name), None


def session_cookie_name(root: Path) -> str:
    """The session cookie's name for a workspace: cookies do not tell ports apart, so two studios on one machine
    (each on its own workspace) would otherwise sign each other out."""
    return "saucerfab-studio-" + hashlib.sha256(str(root).encode()).hexdigest()[:10]


# ---------------------------------------------------------------------------------------------- the middleware


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def _cookie(name: str, value: str, scope: Scope, max_age: int) -> tuple[bytes, bytes]:
    secure = "; Secure" if scope.get("scheme") == "https" else ""  # behind a TLS proxy
    return b"set-cookie", f"{name}={value}; Path=/; Max-Age={max_age}; HttpOnly; SameSite=Strict{secure}".encode()


def safe_next(target: str | None) -> str:
    """A path on this studio to go to after signing in: ``target`` when it is one ("/..."), else ``/``."""
    if not target or not target.startswith("/") or target.startswith(("//", "/\\")) or len(target) > 2000:
        return "/"
    return target if all(" " < c < "\x7f" for c in target) else "/"


def signin_page(message: str | None = None, next_path: str = "/") -> bytes:
    """The sign-in page's HTML (a form posting the token to :data:`LOGIN_PATH`)."""
    try:
        page = SIGNIN_PAGE.read_text(encoding="utf-8")
    except OSError:  # a broken install still gets a form
        page = ('<!doctype html><title>Sign in</title><form method="post" action="/login">__MESSAGE__'
                '<input type="hidden" name="next" value="__NEXT__"><label>Token <input type="password" '
                'name="token"></label> <button>Sign in</button></form>')
    shown = f'<p class="error" role="alert">{html.escape(message)}</p>' if message else ""
    return page.replace("__MESSAGE__", shown).replace("__NEXT__", html.escape(safe_next(next_path))).encode()


async def _send(send: Send, status: int, body: bytes, content_type: str,
                extra: list[tuple[bytes, bytes]] | None = None) -> None:
    headers = [(b"content-type", content_type.encode()), (b"content-length", str(len(body)).encode()),
               (b"cache-control", b"no-store")]
    if status == 401:
        headers.append((b"www-authenticate", b'Bearer realm="saucerfab studio"'))
    if content_type.startswith("text/html"):
        headers.append((b"content-security-policy", PAGE_POLICY.encode()))
    await send({"type": "http.response.start", "status": status, "headers": headers + (extra or [])})
    await send({"type": "http.response.body", "body": body})


async def refuse(send: Send, message: str) -> None:
    """A 401 ``{"error": message}``."""
    await _send(send, 401, json.dumps({"error": message}).encode(), "application/json")


class SignIn:
    """ASGI middleware: every request signs in (token or session cookie) before any route runs.

    The signed-in :class:`User` is put in the scope under :data:`USER_KEY`
    (with no sign-in, the shared user). :data:`LOGIN_PATH` and
    :data:`LOGOUT_PATH` pass through without a user (:func:`login_routes`).

    Args:
        app: the application behind it.
        auth: the users and tokens.
        cookie: the session cookie's name (:func:`session_cookie_name`).
    """

    def __init__(self, app: ASGIApp, auth: Auth, cookie: str) -> None:
        self.app, self.auth, self.cookie = app, auth, cookie

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if not self.auth.required:
            scope[USER_KEY] = user_named(SHARED_USER)
            await self.app(scope, receive, send)
            return
        path, method = scope.get("path", ""), scope.get("method", "GET").upper()
        if path in (LOGIN_PATH, LOGOUT_PATH):
            await self.app(scope, receive, send)
            return
        headers = _headers(scope)
        query = parse_qsl(scope.get("query_string", b"").decode("latin-1"), keep_blank_values=True)
        scheme, _, given = headers.get("authorization", "").strip().partition(" ")
        in_url = [v for k, v in query if k == "token"]
        if scheme.lower() in ("token", "bearer") and given.strip():
            user, how = self.auth.check_token(given.strip()), "the Authorization header"
        elif in_url:
            user, how = self.auth.check_token(in_url[-1]), "the URL"
        else:
            from starlette.requests import cookie_parser

            value = cookie_parser(headers.get("cookie", "")).get(self.cookie)
            user, how = (self.auth.session_user(value), "") if value else (None, "")
        if user is None:
            if path == "/" and method in ("GET", "HEAD"):  # the page: the sign-in form
                shown = _WRONG_IN_URL if how == "the URL" else None
                await _send(send, 401, signin_page(shown), "text/html; charset=utf-8")
            else:
                await refuse(send, f"the token in {how} is not this studio's: {_FIX}" if how else
                             f"sign in first: {_FIX}")
            return
        if how == "the URL" and method in ("GET", "HEAD") and "text/html" in headers.get("accept", ""):
            # a browser's address: set the cookie and go to the same address without the token
            raw = scope.get("raw_path") or quote(path).encode()
            target = "/" + raw.decode("latin-1").lstrip("/")  # never "//host": that would leave the studio
            rest = urlencode([(k, v) for k, v in query if k != "token"])
            location = target + (f"?{rest}" if rest else "")
            await _send(send, 303, b"", "text/plain", [
                (b"location", location.encode("latin-1")),
                _cookie(self.cookie, self.auth.session_value(user), scope, SESSION_MAX_AGE_S)])
            return
        scope[USER_KEY] = user
        await self.app(scope, receive, send)


def login_routes(auth: Auth, cookie: str) -> list[Any]:
    """The routes of the sign-in form (GET and POST :data:`LOGIN_PATH`) and of signing out (POST
    :data:`LOGOUT_PATH`)."""
    from starlette.requests import Request
    from starlette.responses import Response
    from starlette.routing import Route

    def page(message: str | None, status: int, next_path: str) -> Response:
        return Response(signin_page(message, next_path), status_code=status, media_type="text/html",
                        headers={"Cache-Control": "no-store", "Content-Security-Policy": PAGE_POLICY})

    async def form(request: Request) -> Response:
        return page(None, 200, request.query_params.get("next", "/"))

    async def login(request: Request) -> Response:
        body = b""
        async for chunk in request.stream():
            body += chunk
            if len(body) > MAX_FORM_BYTES:
                return page("the sign-in form was too large; paste the token alone", 413, "/")
        fields = dict(parse_qsl(body.decode("utf-8", "replace"), keep_blank_values=True))
        next_path = safe_next(fields.get("next"))
        user = auth.check_token(fields.get("token", "").strip())
        if user is None:
            return page(_WRONG_IN_FORM, 401, next_path)
        r = Response(status_code=303, headers={"Location": next_path, "Cache-Control": "no-store"})
        r.raw_headers.append(_cookie(cookie, auth.session_value(user), request.scope, SESSION_MAX_AGE_S))
        return r

    async def logout(request: Request) -> Response:
        r = Response(status_code=303, headers={"Location": "/", "Cache-Control": "no-store"})
        r.raw_headers.append(_cookie(cookie, "", request.scope, 0))
        return r

    return [Route(LOGIN_PATH, form, methods=["GET"]), Route(LOGIN_PATH, login, methods=["POST"]),
            Route(LOGOUT_PATH, logout, methods=["POST"])]


# ---------------------------------------------------------------------------------------------- logs


_TOKEN_IN_TEXT = re.compile(r"(?i)(\btoken=)[^&\s\"']*")


def redact(text: str) -> str:
    """``text`` with the value of every ``token=`` taken out (``/?token=abc&x=1`` -> ``/?token=[redacted]&x=1``)."""
    return _TOKEN_IN_TEXT.sub(r"\1[redacted]", text)


class RedactTokens(logging.Filter):
    """A logging filter that takes tokens out of a record's message and arguments (uvicorn's access log
    logs each request's path with its query string)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(redact(a) if isinstance(a, str) else a for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {k: redact(v) if isinstance(v, str) else v for k, v in record.args.items()}
        return True


def uvicorn_log_config() -> dict[str, Any]:
    """uvicorn's own logging configuration with :class:`RedactTokens` on both of its handlers."""
    import copy

    from uvicorn.config import LOGGING_CONFIG

    config = copy.deepcopy(LOGGING_CONFIG)
    config.setdefault("filters", {})["no_tokens"] = {"()": f"{__name__}.RedactTokens"}
    for handler in config["handlers"].values():
        handler["filters"] = [*handler.get("filters", []), "no_tokens"]
    return config
