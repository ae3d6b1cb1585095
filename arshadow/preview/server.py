"""The preview's HTTP server: the standard library's ``ThreadingHTTPServer`` on 127.0.0.1, one token.

Routes (every one needs ``?token=T`` or the header ``X-Arshadow-Token: T``; without it: 403):

- ``GET /``: the page (``page.html``, package data: HTML, CSS and script in one file, nothing fetched from
  elsewhere);
- ``GET /api/info``: the input's size and frame count, the starting controls, whether a measured light
  is available;
- ``POST /api/render``: ``{"controls": {...}, "frame": N, "drag_to": [u, v], "mask": bool, "draft": bool}``
  -> the images' addresses, the resolved scene and controls, overlays, the frame's report, server times;
  a request dropped for a newer one: 409;
- ``GET /api/image/ID/composite`` (or ``/mask``): a rendered image, lossless (BMP; the last 8 are kept);
- ``POST /api/save``: writes the scene file of the last image shown (at the path given on the command
  line, never one from the page) -> its path, text and the equivalent command lines.

Every error is JSON ``{"error": "..."}`` with its status (400 a bad request or a scene arshadow refuses,
e.g. a light inside the model, 403 no token or a foreign ``Host``, 404, 405, 409 superseded, 413 too
large, 500 the server's own failure). Nothing but the page and these answers is served:
no path the page sends is ever opened.
"""

from __future__ import annotations

import json
import logging
import re
import secrets
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from ..errors import ArshadowError
from .engine import PreviewEngine
from .worker import Superseded

__all__ = ["PreviewServer", "HOST", "MAX_BODY"]

log = logging.getLogger(__name__)

#: the only address served (nothing reachable from another machine)
HOST = "127.0.0.1"
#: the largest request body read, bytes
MAX_BODY = 64 * 1024
#: what ``_body`` returns after answering an error
_FAILED = object()
#: ``GET /api/image/ID/KIND``: a rendered image's BMP bytes
_IMAGE_ROUTE = re.compile(r"^/api/image/([0-9]{1,12})/(composite|mask)$")


class PreviewServer(ThreadingHTTPServer):
    """``ThreadingHTTPServer`` bound to 127.0.0.1 serving one :class:`PreviewEngine` behind a token.

    Parameters
    ----------
    engine : PreviewEngine
    port : int
        0: any free port.
    info : dict
        Extra facts for ``/api/info`` (the starting controls, the measured light's availability).
    """

    daemon_threads = True
    allow_reuse_address = False

    def __init__(self, engine: PreviewEngine, port: int = 0, info: dict | None = None) -> None:
        super().__init__((HOST, int(port)), _Handler)
        self.engine = engine
        self.token = secrets.token_urlsafe(24)
        self.info = dict(info or {})
        self.page = resources.files(__package__).joinpath("page.html").read_bytes()

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A browser closing its connection is not an error (no traceback on the terminal); others are logged."""
        import sys

        exc = sys.exc_info()[1]
        if isinstance(exc, (ConnectionError, TimeoutError)):
            log.debug("preview: %s: %s", client_address, exc)
            return
        log.error("preview: request from %s failed", client_address, exc_info=exc)

    @property
    def port(self) -> int:
        return int(self.server_address[1])

    @property
    def url(self) -> str:
        """The page's address, token included."""
        return f"http://{HOST}:{self.port}/?token={self.token}"


class _Handler(BaseHTTPRequestHandler):
    server: PreviewServer
    protocol_version = "HTTP/1.1"
    server_version = "arshadow-preview"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the base class's name)
        log.debug("%s " + format, self.address_string(), *args)

    # -- answers ------------------------------------------------------------------------------------
    def _send(self, status: int, body: bytes, ctype: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Referrer-Policy", "no-referrer")
        if ctype.startswith("text/html"):  # the page runs its own inline script, loads nothing from elsewhere
            self.send_header(
                "Content-Security-Policy",
                "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src 'self'; "
                "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'",
            )
        self.end_headers()
        self.wfile.write(body)

    def _json(self, status: int, obj: Any) -> None:
        self._send(status, json.dumps(obj, allow_nan=False).encode("utf-8"), "application/json")

    def _error(self, status: int, message: str) -> None:
        self._json(status, {"error": message, "status": status})

    # -- checks -------------------------------------------------------------------------------------
    def _allowed(self) -> bool:
        """The token (query or header), and a Host header naming this server (a page of another site
        reaching 127.0.0.1 through a rebound name is refused)."""
        host = (self.headers.get("Host") or "").strip().lower()
        if host not in (f"{HOST}:{self.server.port}", f"localhost:{self.server.port}"):
            self._error(HTTPStatus.FORBIDDEN, f"Host {host!r} refused: use {self.server.url.split('?')[0]}")
            return False
        query = parse_qs(urlsplit(self.path).query)
        given = self.headers.get("X-Arshadow-Token") or (query.get("token") or [""])[0]
        if not secrets.compare_digest(given.encode("utf-8"), self.server.token.encode("utf-8")):
            self._error(HTTPStatus.FORBIDDEN, "missing or wrong token: open the address arshadow preview printed")
            return False
        return True

    def _body(self) -> Any:
        """The JSON body (``_FAILED`` after answering an error)."""
        try:
            n = int(self.headers.get("Content-Length") or "0")
        except ValueError:
            n = -1
        if n < 0:
            self._error(HTTPStatus.BAD_REQUEST, "bad Content-Length")
            return _FAILED
        if n > MAX_BODY:
            self._error(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"request body over {MAX_BODY} bytes")
            self.close_connection = True
            return _FAILED
        raw = self.rfile.read(n)
        try:
            return json.loads(raw.decode("utf-8") or "null")
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            self._error(HTTPStatus.BAD_REQUEST, f"the request body is not JSON ({exc})")
            return _FAILED

    # -- routes -------------------------------------------------------------------------------------
    def do_GET(self) -> None:  # noqa: N802 (the base class's name)
        if not self._allowed():
            return
        route = urlsplit(self.path).path
        if route in ("/", "/index.html"):
            self._send(HTTPStatus.OK, self.server.page, "text/html; charset=utf-8")
        elif route == "/api/info":
            self._json(HTTPStatus.OK, self.server.info)
        elif _IMAGE_ROUTE.match(route):
            m = _IMAGE_ROUTE.match(route)
            assert m is not None
            data = self.server.engine.image(int(m.group(1)), m.group(2))
            if data is None:
                self._error(HTTPStatus.NOT_FOUND, f"no image {m.group(1)} {m.group(2)} (only the last ones are kept)")
            else:
                self._send(HTTPStatus.OK, data, "image/bmp")
        elif route in ("/api/render", "/api/save"):
            self._error(HTTPStatus.METHOD_NOT_ALLOWED, f"{route} takes POST")
        else:
            self._error(HTTPStatus.NOT_FOUND, f"no such page: {route}")

    def do_POST(self) -> None:  # noqa: N802
        if not self._allowed():
            return
        route = urlsplit(self.path).path
        if route not in ("/api/render", "/api/save"):
            self._error(HTTPStatus.NOT_FOUND if route != "/" else HTTPStatus.METHOD_NOT_ALLOWED, f"no POST {route}")
            return
        body = self._body()
        if body is _FAILED:
            return
        engine = self.server.engine
        try:
            if route == "/api/save":
                self._json(HTTPStatus.OK, engine.save())
                return
            req = engine.request(body)
            out = engine.render(req)
            if isinstance(body, dict) and "seq" in body:
                out["seq"] = body["seq"]
            self._json(HTTPStatus.OK, out)
        except Superseded as exc:
            self._error(HTTPStatus.CONFLICT, str(exc))
        except ValueError as exc:  # UsageError, MeshError, LightError...: the scene asked for is refused
            self._error(HTTPStatus.BAD_REQUEST, str(exc) or type(exc).__name__)
        except ArshadowError as exc:  # the server's side (no GL context, an unreadable video frame)
            self._error(HTTPStatus.INTERNAL_SERVER_ERROR, str(exc))
        except Exception as exc:  # noqa: BLE001 (one JSON answer per request, the server keeps serving)
            log.exception("preview: %s failed", route)
            self._error(HTTPStatus.INTERNAL_SERVER_ERROR, f"{type(exc).__name__}: {exc}")

    def do_PUT(self) -> None:  # noqa: N802
        if self._allowed():
            self._error(HTTPStatus.METHOD_NOT_ALLOWED, "only GET and POST")

    do_DELETE = do_PATCH = do_PUT  # noqa: N815
