"""Security shared by lipsync's local web servers (``lipsync edit``, ``lipsync serve``).

A page served on ``127.0.0.1`` is still reachable from any web site the user visits: a
foreign page can post to it (cross-site request) or rebind its own DNS name to 127.0.0.1
(DNS rebinding) and then read answers. The guard below refuses both, plus requests without
the session's random token, and bounds request sizes. It is plain ASGI, so it wraps any
Starlette app and covers HTTP and WebSocket handshakes alike.

API
---
:class:`Session` — ``Session.open(host="127.0.0.1", port=0)`` binds the listening socket
first, so a port of 0 becomes the real port before the app is built; it carries

* ``host``, ``port``, ``socket``: where it listens;
* ``token``: ``secrets.token_urlsafe(32)``, required on protected paths as the query
  parameter ``token`` or the header ``X-Lipsync-Token`` (WebSockets: the query parameter,
  as browsers cannot set headers on a handshake);
* ``allowed_hosts``: ``127.0.0.1:PORT``, ``localhost:PORT`` and ``HOST:PORT`` for the bound
  host (plus ``extra_hosts``); ``origins``: ``http://`` + each of them;
* ``url(path="/")``: the address to open, token included.

:class:`Guard` — ASGI middleware, ``Guard(app, session=..., max_body=..., public=...)``:

* ``Host`` not in ``session.allowed_hosts`` → 403 (DNS rebinding);
* ``Origin`` present and not one of ``session.origins`` → 403 (cross-site, also for the
  WebSocket handshake, which browsers send with an Origin and which CORS does not cover);
* token missing or wrong on any path that is not public → 403 (``public``: exact paths and
  prefixes ending in ``/``, by default the page ``/`` and ``/static/``);
* request body over ``max_body`` bytes → 413, decided from ``Content-Length`` before reading
  and, without one, after at most ``max_body + 1`` bytes; the body is handed on to the app
  already read (it is small by construction);
* every response gets ``Referrer-Policy: no-referrer`` (the token must not leak in a
  Referer), ``X-Content-Type-Options: nosniff``, ``X-Frame-Options: DENY`` and a
  same-origin ``Content-Security-Policy`` (``csp=`` to change it).

:func:`run` — ``run(app, session, *, announce=None, ws_max_size=...)`` serves with uvicorn on
the session's socket (printing ``announce`` and the URL first); :func:`start_in_thread`
does the same in a daemon thread and returns a handle whose ``stop()`` ends it (tests,
browser tests).

:func:`resolve_inside` — ``resolve_inside(root, requested)`` → the resolved path of
``requested`` strictly inside ``root`` (after following symlinks), else
:class:`PathRefused`; absolute paths, ``..`` escapes, NUL bytes and links out are refused.

Examples
--------
>>> from starlette.applications import Starlette
>>> from starlette.responses import PlainTextResponse
>>> from starlette.routing import Route
>>> from starlette.testclient import TestClient
>>> session = Session.open()
>>> app = Starlette(routes=[Route("/api/hi", lambda r: PlainTextResponse("hi"))])
>>> client = TestClient(Guard(app, session=session), base_url=session.origin)
>>> client.get("/api/hi").status_code, client.get(f"/api/hi?token={session.token}").text
(403, 'hi')
>>> session.close()
"""

from __future__ import annotations

import os
import secrets
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Optional, Tuple
from urllib.parse import parse_qs, quote

from ..errors import InputError

TOKEN_HEADER = "x-lipsync-token"
TOKEN_PARAM = "token"
# A bank.yaml with 9 visemes x 41 lines is ~40 kB; 1 MiB leaves room for big banks while
# keeping a hostile client from filling memory.
DEFAULT_MAX_BODY = 1 << 20
DEFAULT_CSP = ("default-src 'self'; img-src 'self' data: blob:; style-src 'self'; "
               "script-src 'self'; connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; "
               "form-action 'self'")


class PathRefused(InputError):
    """A requested file is outside the folder a server may read or write."""


@dataclass
class Session:
    """A bound listening socket and the secrets of one server run (see the module docstring).

    Examples
    --------
    >>> s = Session.open(port=0)
    >>> s.port > 0 and s.url("/x").startswith(f"http://127.0.0.1:{s.port}/x?token=")
    True
    >>> s.close()
    """

    host: str
    port: int
    socket: socket.socket
    token: str
    extra_hosts: Tuple[str, ...] = ()
    allowed_hosts: frozenset = field(init=False)
    origins: frozenset = field(init=False)

    def __post_init__(self) -> None:
        names = {"127.0.0.1", "localhost", self.host, *self.extra_hosts}
        if self.host in ("::1", "::"):
            names.add("[::1]")
        hosts = {f"{n}:{self.port}" for n in names if n not in ("0.0.0.0", "::")}
        self.allowed_hosts = frozenset(hosts)
        self.origins = frozenset(f"http://{h}" for h in hosts)

    @classmethod
    def open(cls, host: str = "127.0.0.1", port: int = 0, *, token: Optional[str] = None,
             extra_hosts: Iterable[str] = ()) -> "Session":
        """Bind ``host:port`` (0 = a free port) and make a fresh token.

        Raises :class:`lipsync.errors.InputError` when the port cannot be bound (in use,
        not allowed), naming it.
        """
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise InputError(f"--port must be a whole number 0..65535, got {port!r}")
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            sock.close()
            raise InputError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
        sock.listen(128)
        sock.set_inheritable(True)
        return cls(host=host, port=sock.getsockname()[1], socket=sock,
                   token=token or secrets.token_urlsafe(32), extra_hosts=tuple(extra_hosts))

    @property
    def origin(self) -> str:
        """``http://HOST:PORT`` as a browser on this machine would address it."""
        shown = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        if ":" in shown:
            shown = f"[{shown}]"
        return f"http://{shown}:{self.port}"

    def url(self, path: str = "/") -> str:
        """The address of ``path`` with the token as a query parameter."""
        sep = "&" if "?" in path else "?"
        return f"{self.origin}{path}{sep}{TOKEN_PARAM}={quote(self.token)}"

    def close(self) -> None:
        self.socket.close()


def _header(scope, name: bytes) -> Optional[str]:
    for key, value in scope.get("headers", ()):
        if key == name:
            return value.decode("latin-1")
    return None


def _repeated(scope, names: Tuple[bytes, ...]) -> Optional[str]:
    """The first of ``names`` that the request carries more than once, if any."""
    seen = set()
    for key, _ in scope.get("headers", ()):
        if key in names:
            if key in seen:
                return key.decode("latin-1")
            seen.add(key)
    return None


def _is_public(path: str, public: Tuple[str, ...]) -> bool:
    for p in public:
        if path == p or (p.endswith("/") and p != "/" and path.startswith(p)):
            return True
    return False


class Guard:
    """ASGI middleware enforcing Host, Origin, token and body size (module docstring).

    Parameters
    ----------
    app : ASGI app
    session : Session
    max_body : int
        Largest request body accepted, in bytes.
    public : tuple of str
        Paths served without the token: exact paths, or prefixes ending in ``/``.
    csp : str or None
        Content-Security-Policy of every response (None: no header).

    Examples
    --------
    >>> from starlette.responses import PlainTextResponse
    >>> from starlette.testclient import TestClient
    >>> s = Session.open()
    >>> c = TestClient(Guard(PlainTextResponse("ok"), session=s), base_url=s.origin)
    >>> c.get("/", headers={"host": "evil.example"}).status_code
    403
    >>> s.close()
    """

    def __init__(self, app, *, session: Session, max_body: int = DEFAULT_MAX_BODY,
                 public: Tuple[str, ...] = ("/", "/index.html", "/favicon.ico", "/static/"),
                 csp: Optional[str] = DEFAULT_CSP):
        self.app = app
        self.session = session
        self.max_body = int(max_body)
        self.public = tuple(public)
        self.extra_headers = [(b"referrer-policy", b"no-referrer"), (b"x-content-type-options", b"nosniff"),
                              (b"x-frame-options", b"DENY")]
        if csp:
            self.extra_headers.append((b"content-security-policy", csp.encode()))

    def _refusal(self, scope) -> Optional[Tuple[int, str]]:
        # One Host, one Origin, one token: with two, this guard and whatever reads the
        # request after it could disagree on which one counts (a valid Origin followed by a
        # foreign one passed when only the first was read).
        twice = _repeated(scope, (b"host", b"origin", TOKEN_HEADER.encode()))
        if twice is not None:
            return 400, f"refused: the {twice} header is given more than once"
        host = _header(scope, b"host")
        if host is None or host.lower() not in self.session.allowed_hosts:
            return 403, f"refused: Host {host!r} is not this server (DNS rebinding?)"
        origin = _header(scope, b"origin")
        if origin is not None and origin.lower() not in self.session.origins:
            return 403, f"refused: Origin {origin!r} is not this server (cross-site request)"
        if not _is_public(scope.get("path", ""), self.public):
            given = _header(scope, TOKEN_HEADER.encode())
            if given is None:
                qs = parse_qs(scope.get("query_string", b"").decode("latin-1"))
                given = (qs.get(TOKEN_PARAM) or [None])[0]
            if given is None or not secrets.compare_digest(given.encode(), self.session.token.encode()):
                return 403, "refused: missing or wrong session token (open the URL the server printed)"
        return None

    async def __call__(self, scope, receive, send):
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        refusal = self._refusal(scope)
        if refusal is not None:
            if kind == "websocket":
                # Close before accepting: the browser sees a failed handshake (HTTP 403).
                await send({"type": "websocket.close", "code": 1008, "reason": refusal[1][:120]})
                return
            return await _plain(send, *refusal, self.extra_headers)
        if kind == "websocket":
            return await self.app(scope, receive, send)

        length = _header(scope, b"content-length")
        if length is not None:
            try:
                declared = int(length)
            except ValueError:
                return await _plain(send, 400, "bad Content-Length", self.extra_headers)
            if declared > self.max_body:
                return await _plain(send, 413, f"request body over {self.max_body} bytes", self.extra_headers)
        chunks, total = [], 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            body = message.get("body", b"")
            total += len(body)
            if total > self.max_body:
                return await _plain(send, 413, f"request body over {self.max_body} bytes", self.extra_headers)
            chunks.append(body)
            if not message.get("more_body", False):
                break
        replay = [{"type": "http.request", "body": b"".join(chunks), "more_body": False}]

        async def replay_receive():
            if replay:
                return replay.pop()
            return await receive()

        headers = self.extra_headers

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                message = dict(message)
                message["headers"] = list(message.get("headers", [])) + headers
            await send(message)

        await self.app(scope, replay_receive, send_with_headers)


async def _plain(send, status: int, text: str, headers) -> None:
    body = text.encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                            (b"content-length", str(len(body)).encode())] + list(headers)})
    await send({"type": "http.response.body", "body": body})


def resolve_inside(root, requested, *, must_exist: bool = True) -> Path:
    """The real path of ``requested`` (relative to ``root``), refused unless strictly inside.

    Parameters
    ----------
    root : path-like
        The folder a server may use.
    requested : str
        A path relative to ``root`` as a client sent it.
    must_exist : bool
        Refuse names that do not exist (reading); False for a file about to be written.

    Returns
    -------
    pathlib.Path
        Resolved (symlinks followed) and inside ``root``'s resolved path.

    Raises
    ------
    PathRefused
        Absolute, escaping (``..`` or a symlink out), NUL byte, missing, or the root itself.

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp(); _ = open(os.path.join(d, "a.png"), "wb").write(b"x")
    >>> resolve_inside(d, "a.png").name
    'a.png'
    >>> resolve_inside(d, "../etc/passwd")
    Traceback (most recent call last):
    ...
    lipsync.web.PathRefused: refused: '../etc/passwd' is outside the served folder
    """
    text = os.fspath(requested)
    if not text or "\x00" in text or os.path.isabs(text) or text.startswith(("\\", "~")):
        raise PathRefused(f"refused: {text!r} is outside the served folder")
    base = Path(root).resolve(strict=True)
    try:
        target = (base / text).resolve(strict=False)
    except (OSError, RuntimeError):  # symlink loops
        raise PathRefused(f"refused: {text!r} cannot be resolved") from None
    # Containment first, so a probe outside learns nothing about what exists there.
    if target == base or base not in target.parents:
        raise PathRefused(f"refused: {text!r} is outside the served folder")
    if must_exist and not target.exists():
        raise PathRefused(f"refused: {text!r} does not exist in the served folder")
    return target


def _config(app, session: Session, *, log_level: str, ws_max_size: int):
    import uvicorn

    # limit_concurrency bounds connections a local client can hold open at once; the
    # keep-alive timeout frees idle ones.
    return uvicorn.Config(app, log_level=log_level, ws_max_size=ws_max_size, limit_concurrency=64,
                          timeout_keep_alive=5, lifespan="off", access_log=False)


def run(app, session: Session, *, announce: Optional[str] = None, log_level: str = "warning",
        ws_max_size: int = DEFAULT_MAX_BODY) -> None:
    """Serve ``app`` (already wrapped in :class:`Guard`) on the session's socket until Ctrl-C.

    ``announce`` is printed before the URL (e.g. ``"lipsync edit: open"``).
    """
    import uvicorn

    if announce is not None:
        print(f"{announce} {session.url('/')}", flush=True)
    uvicorn.Server(_config(app, session, log_level=log_level, ws_max_size=ws_max_size)).run(
        sockets=[session.socket])


class _Running:
    def __init__(self, server, thread):
        self.server, self.thread = server, thread

    def stop(self, timeout: float = 5.0) -> None:
        self.server.should_exit = True
        self.thread.join(timeout)


def start_in_thread(app, session: Session, *, log_level: str = "warning",
                    ws_max_size: int = DEFAULT_MAX_BODY, timeout: float = 10.0) -> _Running:
    """Serve in a daemon thread; returns once it accepts connections. ``.stop()`` ends it.

    Examples
    --------
    >>> import httpx
    >>> from starlette.responses import PlainTextResponse
    >>> s = Session.open()
    >>> running = start_in_thread(Guard(PlainTextResponse("ok"), session=s), s)
    >>> httpx.get(s.url("/")).text
    'ok'
    >>> running.stop(); s.close()
    """
    import uvicorn

    server = uvicorn.Server(_config(app, session, log_level=log_level, ws_max_size=ws_max_size))
    server.install_signal_handlers = lambda: None  # not the main thread
    thread = threading.Thread(target=server.run, kwargs={"sockets": [session.socket]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + timeout
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            raise RuntimeError("web server did not start")
        time.sleep(0.01)
    return _Running(server, thread)


__all__ = ["Session", "Guard", "PathRefused", "resolve_inside", "run", "start_in_thread",
           "DEFAULT_MAX_BODY", "TOKEN_HEADER", "TOKEN_PARAM"]
