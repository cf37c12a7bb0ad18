"""The local web app of ``flexreg pick``: a Starlette application over a :class:`PickSession`,
served by uvicorn on 127.0.0.1 only.

Every request must carry the session's random token (query ``token=`` or header
``X-Flexreg-Token``), which is in the URL the command prints: another local user's page cannot
drive the session without it (403). Requests whose ``Host`` is not the loopback address are
refused too (DNS rebinding), and so are requests that change state (POST, PATCH, PUT, DELETE)
from a page of another origin (an ``Origin`` header other than the page's own). Request bodies
are limited to :data:`MAX_BODY_BYTES` (413; a chunked body is read no further than that). Bad
requests get a JSON error (``{"error": "..."}``, status 400, 403, 404 or 413); an unexpected
failure is logged and answered with status 500; the server keeps running.
"""

from __future__ import annotations

import json
import logging
import secrets
import socket
import threading
from collections.abc import Awaitable, Callable
from importlib import resources
from typing import Any
from urllib.parse import urlsplit

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from flexreg.errors import FlexregError, InputError
from flexreg.picker.session import PickSession

log = logging.getLogger(__name__)

__all__ = ["PickerServer", "create_app", "new_token"]

#: host names the server answers to (it listens on 127.0.0.1 only)
LOCAL_HOSTS = ("127.0.0.1", "localhost")
#: the page's files (package data), with their content types
STATIC = {
    "picker.js": "text/javascript; charset=utf-8",
    "picker.css": "text/css; charset=utf-8",
}
#: largest request body accepted (the page's requests are a few hundred bytes of JSON)
MAX_BODY_BYTES = 1 << 20
#: methods that change the session's state: refused from a page of another origin
UNSAFE_METHODS = frozenset({"POST", "PATCH", "PUT", "DELETE"})


def new_token() -> str:
    """A random session token (192 bits, URL-safe)."""
    return secrets.token_urlsafe(24)


def _same_origin(origin: str, scheme: str, host: str) -> bool:
    """Whether the ``Origin`` header names ``scheme://host`` (the ``Host`` header's name and
    port, default ports filled in)."""
    default = {"http": 80, "https": 443}.get(scheme)
    try:
        o, h = urlsplit(origin), urlsplit(f"//{host}")
        return (
            o.scheme == scheme
            and o.hostname is not None
            and o.hostname == h.hostname
            and (o.port or default) == (h.port or default)
            and o.path in ("", "/")
        )
    except ValueError:  # a malformed port
        return False


class _Guard:
    """ASGI middleware on every HTTP request: a loopback ``Host``, the page's own ``Origin``
    (when given) on requests that change state, the token, and a body of at most
    ``max_body`` bytes (read here, then handed on to the application)."""

    def __init__(
        self, app: ASGIApp, token: str, hosts: tuple[str, ...], max_body: int = MAX_BODY_BYTES
    ) -> None:
        self.app, self.token, self.hosts, self.max_body = app, token, hosts, max_body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request = Request(scope)
        problem, status = self._refusal(request, scope.get("scheme", "http"))
        if problem is None:
            body = await self._read_body(receive)
            if body is None:  # the client went away
                return
            if len(body) <= self.max_body:
                await self.app(scope, _replay(body, receive), send)
                return
            problem, status = self._too_large(), 413
        await JSONResponse({"error": problem}, status_code=status)(scope, receive, send)

    def _refusal(self, request: Request, scheme: str) -> tuple[str | None, int]:
        """Why the request is refused, from its headers alone, with the status; (None, 200)
        when it may proceed."""
        host_header = request.headers.get("host") or ""
        host = host_header.rsplit(":", 1)[0].strip("[]")
        given = request.query_params.get("token") or request.headers.get("x-flexreg-token") or ""
        origin = request.headers.get("origin")
        if host not in self.hosts:
            return f"host {host!r} refused: open the page at 127.0.0.1", 403
        if (
            request.method in UNSAFE_METHODS
            and origin is not None
            and not _same_origin(origin, scheme, host_header)
        ):
            return f"origin {origin!r} refused: only the picker's own page may change it", 403
        if not secrets.compare_digest(given.encode(), self.token.encode()):
            return "missing or wrong session token: open the URL flexreg pick printed", 403
        declared = request.headers.get("content-length")
        if declared is not None and not (declared.isascii() and declared.strip().isdigit()):
            return f"invalid Content-Length {declared!r}", 400
        if declared is not None and int(declared) > self.max_body:
            return self._too_large(), 413
        return None, 200

    def _too_large(self) -> str:
        return f"request body larger than {self.max_body} bytes refused"

    async def _read_body(self, receive: Receive) -> bytes | None:
        """The request body, read no further than ``max_body + 1`` bytes (a longer one is
        cut there: the caller refuses it); None when the client disconnects."""
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return None
            chunk = message.get("body", b"")
            chunks.append(chunk)
            size += len(chunk)
            if size > self.max_body or not message.get("more_body", False):
                return b"".join(chunks)


def _replay(body: bytes, receive: Receive) -> Receive:
    """An ASGI ``receive`` that gives ``body`` whole once, then defers to ``receive``."""
    pending = True

    async def replay() -> Message:
        nonlocal pending
        if pending:
            pending = False
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay


Handler = Callable[[Request], Awaitable[Response]]


def _json_errors(fn: Callable[[Request], Any]) -> Handler:
    """Run a synchronous handler in a worker thread; its result as JSON (a Response as it is),
    a known error as ``{"error": ...}`` with 400 (404 for an unknown pair or suggestion),
    anything else logged and answered with 500."""
    from starlette.concurrency import run_in_threadpool

    async def endpoint(request: Request) -> Response:
        try:
            body: Any = {}
            if request.method in ("POST", "PATCH"):
                raw = await request.body()
                if raw:
                    try:
                        body = json.loads(raw)
                    except ValueError:
                        raise InputError("request", "the body is not valid JSON") from None
                    except RecursionError:  # json's decoder recurses once per nesting level
                        raise InputError("request", "the body is nested too deeply") from None
                    if not isinstance(body, dict):
                        raise InputError("request", "the body must be a JSON object")
            request.state.body = body
            out = await run_in_threadpool(fn, request)
        except InputError as e:
            code = 404 if e.source in ("pair", "suggestion") else 400
            return JSONResponse({"error": str(e)}, status_code=code)
        except FlexregError as e:
            return JSONResponse({"error": str(e)}, status_code=400)
        except Exception as e:  # a bug must not take the session down with unsaved pairs
            log.exception("picker request %s %s failed", request.method, request.url.path)
            return JSONResponse({"error": f"internal error: {e}"}, status_code=500)
        return out if isinstance(out, Response) else JSONResponse(out)

    return endpoint


def _png(data: bytes) -> Response:
    return Response(data, media_type="image/png", headers={"Cache-Control": "no-store"})


def _static(name: str) -> str:
    return resources.files("flexreg.picker").joinpath("static").joinpath(name).read_text("utf-8")


def create_app(
    session: PickSession,
    token: str,
    *,
    hosts: tuple[str, ...] = LOCAL_HOSTS,
    max_body: int = MAX_BODY_BYTES,
) -> ASGIApp:
    """The ASGI application of a picking session.

    Parameters
    ----------
    session : PickSession
    token : str
        Required on every request.
    hosts : tuple of str
        Accepted ``Host`` names.
    max_body : int, bytes
        Largest request body accepted (413 beyond).

    Returns
    -------
    ASGI application
    """
    s = session

    def index(request: Request) -> Response:
        html = _static("index.html").replace("{{TOKEN}}", token)
        return Response(html, media_type="text/html; charset=utf-8")

    def static(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in STATIC:
            raise InputError("static", f"no file {name!r}")
        return Response(_static(name), media_type=STATIC[name])

    def q(request: Request, key: str) -> str:
        if key not in request.query_params:
            raise InputError("request", f"missing query parameter {key!r}")
        return request.query_params[key]

    def full(request: Request) -> bool:
        return request.query_params.get("full") == "1"

    def body(request: Request) -> dict[str, Any]:
        return dict(request.state.body)

    def add(request: Request) -> Any:
        b = body(request)
        s.add_pair(b.get("u"), b.get("v"), str(b.get("mode", "flexion")), b.get("x"), b.get("y"))
        return s.state()

    def move(request: Request) -> Any:
        s.move_pair(request.path_params["pid"], body(request))
        return s.state()

    def delete(request: Request) -> Any:
        s.delete_pair(request.path_params["pid"])
        return s.state()

    def suggest(request: Request) -> Any:
        s.suggest()
        return s.state()

    def accept(request: Request) -> Any:
        s.accept(request.path_params["sid"])
        return s.state()

    def reject(request: Request) -> Any:
        s.reject(request.path_params["sid"])
        return s.state()

    def save(request: Request) -> Any:
        s.save()
        return s.state()

    routes = [
        Route("/", _json_errors(index)),
        Route("/static/{name}", _json_errors(static)),
        Route("/api/state", _json_errors(lambda r: s.state())),
        Route("/api/camera.png", _json_errors(lambda r: _png(s.camera_png(full=full(r))))),
        Route(
            "/api/lidar/{mode}.png",
            _json_errors(lambda r: _png(s.lidar_png(r.path_params["mode"], full=full(r)))),
        ),
        Route(
            "/api/overlay.png",
            _json_errors(lambda r: _png(s.overlay_png(r.query_params.get("zoom", 1.0)))),
        ),
        Route("/api/snap", _json_errors(lambda r: s.snap(q(r, "mode"), q(r, "x"), q(r, "y")))),
        Route(
            "/api/predict",
            _json_errors(lambda r: {"lidar": s.predict_lidar(q(r, "u"), q(r, "v"), q(r, "mode"))}),
        ),
        Route("/api/pairs", _json_errors(add), methods=["POST"]),
        Route("/api/pairs/{pid}", _json_errors(move), methods=["PATCH"]),
        Route("/api/pairs/{pid}", _json_errors(delete), methods=["DELETE"]),
        Route("/api/suggestions", _json_errors(suggest), methods=["POST"]),
        Route("/api/suggestions/{sid}/accept", _json_errors(accept), methods=["POST"]),
        Route("/api/suggestions/{sid}/reject", _json_errors(reject), methods=["POST"]),
        Route("/api/save", _json_errors(save), methods=["POST"]),
    ]
    return _Guard(Starlette(routes=routes), token, hosts, max_body)


class PickerServer:
    """A picking session served on ``127.0.0.1:port`` (0: a free port), in the foreground
    (:meth:`run`) or in a thread (:meth:`start`, :meth:`stop`).

    Attributes
    ----------
    url : str
        The page's address with the token.
    """

    def __init__(self, session: PickSession, *, port: int = 0, token: str | None = None) -> None:
        import uvicorn  # heavy: loads only for the pick command

        self.session = session
        self.token = token or new_token()
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._socket.bind(("127.0.0.1", int(port)))
        except OSError as e:
            self._socket.close()
            raise InputError("--port", f"cannot listen on 127.0.0.1:{port}: {e.strerror}") from None
        self._socket.listen(128)  # connections wait in the backlog until uvicorn serves them
        self.port = int(self._socket.getsockname()[1])
        self.url = f"http://127.0.0.1:{self.port}/?token={self.token}"
        config = uvicorn.Config(
            create_app(session, self.token), log_level="warning", lifespan="off", access_log=False
        )
        self._server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    def run(self) -> None:
        """Serve until interrupted: Ctrl-C or SIGTERM shut the server down gracefully, then
        raise :class:`KeyboardInterrupt` (uvicorn re-raises the signal after its shutdown)."""
        import signal

        def interrupted(signum: int, frame: object) -> None:
            raise KeyboardInterrupt

        main = threading.current_thread() is threading.main_thread()
        old = signal.signal(signal.SIGTERM, interrupted) if main else None
        try:
            self._server.run(sockets=[self._socket])
        finally:
            self._socket.close()
            if main:
                signal.signal(signal.SIGTERM, old)

    def start(self, timeout_s: float = 30.0) -> None:
        """Serve in a daemon thread; return once it accepts connections."""
        import time

        self._thread = threading.Thread(target=self.run, name="flexreg-pick", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        pause = threading.Event()
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise FlexregError(f"the picker server did not start within {timeout_s:g} s")
            pause.wait(0.02)

    def stop(self) -> None:
        """Stop a server started with :meth:`start`."""
        self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=10)
