"""A static file server for the viewer folder, bound to 127.0.0.1 (``http.server`` in a thread)."""

from __future__ import annotations

import functools
import http.server
import threading
from pathlib import Path

from prefilter.errors import PrefilterError

__all__ = ["serve"]


class _Handler(http.server.SimpleHTTPRequestHandler):
    # ES modules need a JavaScript MIME type whatever the platform's mimetypes table says
    extensions_map = {**http.server.SimpleHTTPRequestHandler.extensions_map,
                      ".js": "text/javascript", ".glsl": "text/plain", ".json": "application/json",
                      ".bin": "application/octet-stream"}

    def log_message(self, format, *args):  # noqa: A002 - quiet: the CLI prints the URL
        pass

    def end_headers(self):
        self.send_header("Cache-Control", "no-store")
        super().end_headers()


def serve(directory, port: int = 0, host: str = "127.0.0.1", *, background: bool = True):
    """Serve ``directory`` at ``http://host:port/`` (``port=0``: a free port).

    Returns ``(server, url)``; with ``background=True`` the server runs in a daemon thread (stop
    it with ``server.shutdown()``), otherwise the caller runs ``server.serve_forever()``.
    """
    d = Path(directory)
    if not (d / "index.html").is_file():
        raise PrefilterError(f"directory: expected a viewer folder with index.html, got {d}")
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise PrefilterError(f"port: expected an integer in [0, 65535], got {port!r}")
    handler = functools.partial(_Handler, directory=str(d))
    try:
        server = http.server.ThreadingHTTPServer((host, port), handler)
    except OSError as exc:
        raise PrefilterError(f"port: cannot listen on {host}:{port} ({exc.strerror})") from None
    server.daemon_threads = True
    url = f"http://{host}:{server.server_address[1]}/"
    if background:
        threading.Thread(target=server.serve_forever, daemon=True, name="prefilter-viewer").start()
    return server, url
