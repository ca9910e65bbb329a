"""Serving a page with Python's own :mod:`http.server`, bound to the loopback address ``127.0.0.1`` only."""

from __future__ import annotations

import http.server
import os
import sys
from pathlib import Path

from .._errors import DataNotFoundError, InputError

HOST = "127.0.0.1"


def _handler(body: bytes):
    class Handler(http.server.BaseHTTPRequestHandler):
        """``GET /`` and ``GET /index.html`` answer the page; anything else 404."""

        def do_GET(self):  # noqa: N802 - the name http.server calls
            if self.path.split("?")[0] not in ("/", "/index.html"):
                self.send_error(404)
                return
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format, *args):  # noqa: A002 - quiet: the address line is the output
            pass

    return Handler


def make_server(path: str | os.PathLike, port: int = 0) -> http.server.ThreadingHTTPServer:
    """A server of the page at ``path`` on ``127.0.0.1:port`` (``0``: a free port; ``server.server_port`` says
    which). Not started: call ``serve_forever``."""
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"page {str(path)!r}: no such file")
    if not 0 <= int(port) <= 65535:
        raise InputError(f"port: expected 0 (any free port) or a port in [1, 65535], found {port}")
    return http.server.ThreadingHTTPServer((HOST, int(port)), _handler(path.read_bytes()))


def serve_page(path: str | os.PathLike, port: int = 0) -> None:
    """Serve the page at ``path`` on ``http://127.0.0.1:<port>/`` until interrupted; prints the address first."""
    server = make_server(path, port)
    print(f"serving {path} at http://{HOST}:{server.server_port}/ (Ctrl-C stops)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopped", file=sys.stderr)
    finally:
        server.server_close()
