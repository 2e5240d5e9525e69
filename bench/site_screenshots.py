"""Screenshots of the built documentation site in headless Chromium (docs/measurements/site.md).

Run: ``.venv/bin/python -m bench.site_screenshots [--site site] [--out docs/measurements]``
after ``make docs``. Serves the built site on 127.0.0.1 (an ephemeral port), loads the home
page and the flight operator's guide in Debian's Chromium (``tests/app/headless.py``, the
live page test's driver), waits until each page has laid out its navigation and tables,
and writes ``site-home.png`` and ``site-operator.png``.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import shutil
import threading
import time
from pathlib import Path

from tests.app.headless import HeadlessChromium

PAGES = {"site-home.png": "index.html", "site-operator.png": "operator.html"}
"""Screenshot file → page of the built site."""

WIDTH, HEIGHT = 1280, 900
"""Viewport, CSS pixels: a laptop's browser window."""

READY_TIMEOUT_S = 30.0
"""Longest wait for a page to finish loading, s."""


def _serve(site: Path) -> http.server.ThreadingHTTPServer:
    """An HTTP server of ``site`` on 127.0.0.1, running on its own thread."""

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, format: str, *args: object) -> None:
            pass

    handler = functools.partial(Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def _wait_loaded(browser: HeadlessChromium) -> None:
    """Wait until the document has loaded and its stylesheet applied."""
    deadline = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < deadline:
        ready = browser.evaluate(
            "document.readyState === 'complete' && "
            "getComputedStyle(document.body).fontFamily !== ''"
        )
        if ready:
            time.sleep(0.5)  # Material's script lays out the navigation after load
            return
        time.sleep(0.1)
    raise RuntimeError(f"page not loaded within {READY_TIMEOUT_S} s")


def main(argv: list[str] | None = None) -> int:
    """Take the screenshots; the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", type=Path, default=Path("site"), help="built site (make docs)")
    ap.add_argument("--out", type=Path, default=Path("docs/measurements"), help="PNG folder")
    args = ap.parse_args(argv)
    executable = shutil.which("chromium") or shutil.which("chromium-browser")
    if executable is None:
        raise SystemExit("chromium not found (Debian: apt-get install chromium)")
    if not (args.site / "index.html").exists():
        raise SystemExit(f"{args.site}/index.html missing: run make docs first")
    server = _serve(args.site)
    try:
        with HeadlessChromium(executable, WIDTH, HEIGHT) as browser:
            for name, page in PAGES.items():
                browser.navigate(f"http://127.0.0.1:{server.server_port}/{page}")
                _wait_loaded(browser)
                print(browser.screenshot(args.out / name))
    finally:
        server.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
