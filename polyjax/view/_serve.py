"""Serving a page with Python's own :mod:`http.server`, bound to the loopback address ``127.0.0.1`` only.

The server answers only requests whose ``Host`` header names the loopback address and its port
(``127.0.0.1:PORT`` or ``localhost:PORT``): a page of another site that a browser was led to fetch from this port
(DNS rebinding: a name of that site made to point at ``127.0.0.1``) gets ``403 Forbidden``, never the page. The port
is bound before the page is written (:func:`open_server`), so a busy port fails before any work.
"""

from __future__ import annotations

import http.server
import os
import sys
from pathlib import Path

from .._errors import DataNotFoundError, InputError

HOST = "127.0.0.1"


class _Handler(http.server.BaseHTTPRequestHandler):
    """``GET /`` and ``GET /index.html`` answer the page (``server.page``); a foreign ``Host`` 403; anything else
    404."""

    def do_GET(self):  # noqa: N802 - the name http.server calls
        port = self.server.server_port
        if (self.headers.get("Host") or "").strip().lower() not in (f"{HOST}:{port}", f"localhost:{port}"):
            self.send_error(403, "this server answers only http://127.0.0.1:PORT/ and http://localhost:PORT/")
            return
        if self.path.split("?")[0] not in ("/", "/index.html"):
            self.send_error(404)
            return
        body = self.server.page
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format, *args):  # noqa: A002 - quiet: the address line is the output
        pass


def open_server(port: int = 0, flag: str = "port") -> http.server.ThreadingHTTPServer:
    """A server bound to ``127.0.0.1:port`` (``0``: a free port; ``server.server_port`` says which) with an empty
    page (set ``server.page`` to the page's bytes). Not started: call ``serve_forever``.

    Raises:
        InputError: a port outside ``[0, 65535]``, or one that cannot be bound (in use), naming ``flag``.
    """
    if not 0 <= int(port) <= 65535:
        raise InputError(f"{flag}: expected 0 (any free port) or a port in [1, 65535], found {port}")
    try:
        server = http.server.ThreadingHTTPServer((HOST, int(port)), _Handler)
    except OSError as e:
        raise InputError(f"{flag} {port}: cannot listen on {HOST}:{port} ({e.strerror or e}; in use? "
                         f"--port 0 picks a free one)") from None
    server.page = b""
    return server


def make_server(path: str | os.PathLike, port: int = 0) -> http.server.ThreadingHTTPServer:
    """A server of the page at ``path`` on ``127.0.0.1:port`` (:func:`open_server`). Not started: call
    ``serve_forever``."""
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"page {str(path)!r}: no such file")
    server = open_server(port)
    server.page = path.read_bytes()
    return server


def serve_page(path: str | os.PathLike, port: int = 0, server: http.server.ThreadingHTTPServer | None = None) -> None:
    """Serve the page at ``path`` on ``http://127.0.0.1:<port>/`` until interrupted (on ``server`` when given, a
    server of :func:`open_server` bound before the page was written); prints the address first."""
    if server is None:
        server = make_server(path, port)
    else:
        server.page = Path(path).read_bytes()
    print(f"serving {path} at http://{HOST}:{server.server_port}/ (Ctrl-C stops)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopped", file=sys.stderr)
    finally:
        server.server_close()
