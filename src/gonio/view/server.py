"""Serve one page on 127.0.0.1 until Ctrl-C: only at a random-token path, nothing from disk."""

from __future__ import annotations

import http.server
import secrets
import sys
import threading
import webbrowser
from collections.abc import Callable


class PageServer(http.server.ThreadingHTTPServer):
    """An HTTP server bound to 127.0.0.1 that answers ``GET /<token>/`` with the page and
    404 to every other request (no file is ever read from disk)."""

    daemon_threads = True

    def __init__(self, page: str, port: int = 0) -> None:
        self.token = secrets.token_urlsafe(24)
        self.body = page.encode("utf-8")
        super().__init__(("127.0.0.1", port), _Handler)

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}/{self.token}/"


class _Handler(http.server.BaseHTTPRequestHandler):
    server: PageServer

    def do_GET(self) -> None:
        if self.path.split("?", 1)[0] != f"/{self.server.token}/":
            self.send_error(404)
            return
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(self.server.body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("Referrer-Policy", "no-referrer")
        self.end_headers()
        self.wfile.write(self.server.body)

    def log_message(self, format: str, *args: object) -> None:  # quiet
        return


def serve(
    page: str,
    *,
    port: int = 0,
    open_browser: bool = True,
    ready: Callable[[PageServer], None] | None = None,
) -> None:
    """Serve ``page`` until Ctrl-C (or until ``server.shutdown()``); print its URL and open it
    in the default browser. ``ready`` is called with the running server (tests stop it)."""
    server = PageServer(page, port)
    try:
        print(f"serving {server.url} (127.0.0.1 only; Ctrl-C to stop)", file=sys.stderr)
        if open_browser:
            threading.Thread(target=webbrowser.open, args=(server.url,), daemon=True).start()
        if ready is not None:
            ready(server)
        try:
            server.serve_forever()
        except KeyboardInterrupt:  # Ctrl-C: the CLI reports it as every command does
            pass
    finally:
        server.server_close()
