"""Counters, health and the local status endpoint.

:class:`Counters` is a thread-safe registry that every part of the daemon
increments (or that pulls numbers from the parts' own counters at read time).
:class:`Health` holds one state per component (INS, radar, recorder,
processing). :class:`StatusServer` serves both over HTTP on the loopback
interface only:

- ``GET /status``: JSON ``{"healthy", "uptime_s", "components", "counters", "gauges"}``;
- ``GET /health``: 200 ``ok`` when every component is healthy, else 503 and the failing ones;
- ``GET /``: the operator's live page (:data:`LIVE_PAGE`), with ``GET /tiles/latest.png``
  (the newest tiles, :class:`LiveView`) and ``GET /live.json`` (tiles, autofocus
  estimates, disk left), when the server is given the run's store;
- ``GET /metrics``: the same numbers in the Prometheus text format (0.0.4):
  counters as ``sarmoco_<name>_total``, gauges as ``sarmoco_<name>``, health as
  ``sarmoco_component_up{component="..."}``.

The endpoint is read-only: any other method is answered 405. Each connection has its
own thread, and one that does not finish its request within
:data:`REQUEST_TIMEOUT_S` is closed, so a slow or stalled client holds nothing.
"""

from __future__ import annotations

import json
import logging
import math
import re
import shutil
import socket
import threading
import time
from collections.abc import Callable, Mapping
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sarmoco.daemon.livefeed import LIVE_TILES, LiveFeed
from sarmoco.daemon.livelevel import level_names
from sarmoco.errors import ConfigError
from sarmoco.grayscale import gray_of, peak_blocks, png_gray

log = logging.getLogger(__name__)

STATUS_HOSTS = ("127.0.0.1", "::1", "localhost")
"""The only addresses the status server binds to."""

REQUEST_TIMEOUT_S = 5.0
"""Longest a connection may take to send its request, s."""

_NAME_BAD = re.compile(r"[^a-zA-Z0-9_]")


def metric_name(name: str) -> str:
    """A Prometheus-safe metric name (``[a-zA-Z0-9_]``, not starting with a digit)."""
    clean = _NAME_BAD.sub("_", name)
    return f"_{clean}" if clean[:1].isdigit() else clean


class Counters:
    """Thread-safe counters (monotonic) and gauges (current values).

    Parameters
    ----------
    prefix : str
        Prefix of the Prometheus metric names.
    """

    def __init__(self, prefix: str = "sarmoco") -> None:
        self.prefix = prefix
        self._lock = threading.Lock()
        self._counters: dict[str, float] = {}
        self._gauges: dict[str, float] = {}
        self._sources: list[tuple[str, Callable[[], Mapping[str, float]], bool]] = []

    def inc(self, name: str, n: float = 1) -> None:
        """Add ``n`` to counter ``name`` (created at 0)."""
        with self._lock:
            self._counters[name] = self._counters.get(name, 0) + n

    def set(self, name: str, value: float) -> None:
        """Set gauge ``name`` (e.g. ``ins_age_s``, ``backlog_pulses``, ``pulse_rate_hz``)."""
        with self._lock:
            self._gauges[name] = value

    def add_source(
        self, prefix: str, read: Callable[[], Mapping[str, float]], counters: bool = True
    ) -> None:
        """Read numbers from a part's own counters at every snapshot.

        Parameters
        ----------
        prefix : str
            Prepended to each key with ``_`` (e.g. ``"nav"`` gives ``nav_kinematics_stale``).
        read : callable
            Returns the current numbers, e.g. ``NavBuffer.counts`` or
            ``lambda: driver.counters.snapshot()``; called from the server thread.
        counters : bool
            True when the numbers only grow (counters), False for gauges.

        A source added under a prefix already in use replaces the earlier one (a new
        store's pipeline takes over from the last one's).
        """
        with self._lock:
            self._sources = [s for s in self._sources if s[0] != prefix]
            self._sources.append((prefix, read, counters))

    def snapshot(self) -> dict[str, dict[str, float]]:
        """Current ``{"counters": {...}, "gauges": {...}}``."""
        with self._lock:
            counters, gauges = dict(self._counters), dict(self._gauges)
            sources = list(self._sources)
        for prefix, read, is_counter in sources:
            target = counters if is_counter else gauges
            for key, value in read().items():
                target[f"{prefix}_{key}"] = float(value)
        return {"counters": counters, "gauges": gauges}


class Health:
    """Health of each component: ok or not, with a short reason."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._state: dict[str, tuple[bool, str]] = {}

    def set(self, component: str, ok: bool, detail: str = "") -> None:
        """Record the state of ``component`` (e.g. ``"ins"``, ``"radar"``, ``"recorder"``)."""
        with self._lock:
            self._state[component] = (ok, detail)

    def components(self) -> dict[str, dict[str, Any]]:
        """``{component: {"ok": bool, "detail": str}}``."""
        with self._lock:
            return {k: {"ok": ok, "detail": d} for k, (ok, d) in self._state.items()}

    @property
    def healthy(self) -> bool:
        """True when every component reported so far is ok (and at least one has)."""
        with self._lock:
            return bool(self._state) and all(ok for ok, _ in self._state.values())


def prometheus_text(counters: Counters, health: Health) -> str:
    """The registry and health in the Prometheus text exposition format."""
    snap = counters.snapshot()
    lines: list[str] = []
    for kind, suffix in (("counters", "_total"), ("gauges", "")):
        for name, value in sorted(snap[kind].items()):
            full = f"{counters.prefix}_{metric_name(name)}{suffix}"
            lines.append(f"# TYPE {full} {'counter' if kind == 'counters' else 'gauge'}")
            lines.append(f"{full} {_number(value)}")
    up = f"{counters.prefix}_component_up"
    lines.append(f"# TYPE {up} gauge")
    for component, state in sorted(health.components().items()):
        label = component.replace("\\", "\\\\").replace('"', '\\"')
        lines.append(f'{up}{{component="{label}"}} {1 if state["ok"] else 0}')
    return "\n".join(lines) + "\n"


def _number(value: float) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "+Inf" if value > 0 else "-Inf"
    return repr(int(value)) if float(value).is_integer() else repr(float(value))


LIVE_STRIP_PX = 1200
"""Width of the live strip, pixels (each tile is decimated to its share once)."""


class LiveView:
    """The live page's data, from the run's :class:`~sarmoco.daemon.livefeed.LiveFeed`
    (handed over in memory by the recorder; the store is never opened).

    The newest finished tiles are rendered to one PNG strip in the HTTP thread that asks
    for it, at most once per ``min_interval_s`` and only when a tile was added since (the
    processing thread never renders); other requests get the last PNG. Each tile is
    decimated once; a new strip is put on one dB scale (re the brightest of its tiles, so
    that tiles of noise beside the scene stay dark) and re-encoded.

    Parameters
    ----------
    store_path : Path
        The run's store (it may not exist yet): only the free space of its file system
        is read.
    feed : LiveFeed
        What the run's recorder hands over: tile count, newest tiles, autofocus estimates.
    min_interval_s : float
        Shortest time between two renderings, s.
    """

    def __init__(self, store_path: Path, feed: LiveFeed, min_interval_s: float = 1.0) -> None:
        self.store_path = store_path
        self.feed = feed
        self.min_interval_s = min_interval_s
        self._lock = threading.Lock()
        self._png: bytes | None = None
        self._mag: dict[int, tuple[float, npt.NDArray[np.float32]]] = {}
        """Tile index to (start along track m, decimated magnitude) of the tiles on the strip."""
        self._tiles_drawn = 0
        self._last_render = -math.inf
        self.renders = 0
        """PNG strips rendered so far."""
        self.render_s = 0.0
        """Thread CPU time spent rendering them, s."""

    def png(self) -> bytes | None:
        """The newest tiles as one PNG strip (along track left to right); None before any."""
        with self._lock:
            now = time.monotonic()
            if now - self._last_render < self.min_interval_s:
                return self._png
            snap = self.feed.snapshot()
            if snap.n_tiles == self._tiles_drawn:
                return self._png
            t0 = time.thread_time()
            width = LIVE_STRIP_PX // LIVE_TILES
            self._mag = {
                t.index: self._mag.get(t.index) or (t.x0_m, peak_blocks(t.data, width))
                for t in snap.tiles
            }
            parts = sorted(self._mag.values(), key=lambda part: part[0])
            rows = min(m.shape[0] for _, m in parts)  # far range at the top: keep the bottom
            mag = np.concatenate([m[m.shape[0] - rows :] for _, m in parts], 1)
            self._png = png_gray(gray_of(mag, float(mag.max()) if mag.size else 0.0))
            self.render_s += time.thread_time() - t0
            self.renders += 1
            self._tiles_drawn, self._last_render = snap.n_tiles, now
            return self._png

    def summary(self) -> dict[str, Any]:
        """``/live.json``: tiles recorded, autofocus estimates, disk, rendering cost."""
        snap = self.feed.snapshot()
        out: dict[str, Any] = {
            "tiles": snap.n_tiles,
            "autofocus": snap.autofocus,
            "disk_free_bytes": None,
            "disk_total_bytes": None,
            "png_renders": self.renders,
            "png_render_cpu_s": round(self.render_s, 6),
        }
        folder = self.store_path if self.store_path.exists() else self.store_path.parent
        try:
            usage = shutil.disk_usage(folder)
            out["disk_free_bytes"], out["disk_total_bytes"] = usage.free, usage.total
        except OSError:
            pass
        return out


LIVE_PAGE_POLL_S = 2.0
"""The live page's refresh interval (its script's timer), s."""

LIVE_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>sarmoco live</title>
<style>
body{font-family:sans-serif;margin:1em;background:#111;color:#ddd}
table{border-collapse:collapse}td{padding:2px 10px}
.bad{color:#f66}.ok{color:#6d6}#strip{width:100%;image-rendering:pixelated;background:#000}
svg{background:#000}
</style></head><body>
<h1>sarmoco live</h1>
<p>Newest focused tiles (along track left to right, far range at the top, 40 dB):</p>
<img id="strip" alt="no tile yet">
<h2>Links</h2><table id="health"></table>
<h2>Run</h2><table id="run"></table>
<h2>Autofocus estimates (a_y red, a_z cyan, m/s&sup2;)</h2>
<svg id="af" width="600" height="160"></svg>
<script>
"use strict";
let last = null;
const LEVELS = __LIVE_LEVELS__;
function row(k, v, cls) {
  return "<tr><td>" + k + "</td><td class='" + (cls || "") + "'>" + v + "</td></tr>";
}
function esc(s) {
  return String(s).replace(/[&<>]/g, c => ({"&": "&amp;", "<": "&lt;", ">": "&gt;"})[c]);
}
async function status() {
  const s = await (await fetch("status")).json();
  const c = s.counters, g = s.gauges;
  let h = "";
  for (const [k, v] of Object.entries(s.components))
    h += row(esc(k), (v.ok ? "ok " : "FAILED ") + esc(v.detail), v.ok ? "ok" : "bad");
  document.getElementById("health").innerHTML = h;
  const now = performance.now(), n = c.pipeline_pulses_received || 0;
  const rate = last ? (n - last[1]) / ((now - last[0]) / 1000) : NaN;
  last = [now, n];
  let drops = 0;
  for (const [k, v] of Object.entries(c)) if (k.includes("drop")) drops += v;
  const l = await (await fetch("live.json")).json();
  document.getElementById("run").innerHTML =
    row("INS age", (g.ins_age_seconds ?? NaN).toFixed(2) + " s") +
    row("pulse rate", rate.toFixed(0) + " /s") +
    row("pulses", n) + row("dropped", drops, drops ? "bad" : "") +
    row("backlog", (g.echo_backlog_pulses ?? 0) + " pulses") +
    (g.live_image_level === undefined ? "" :
      row("live image", LEVELS[g.live_image_level] + ", load " +
          g.live_image_load.toFixed(2), g.live_image_level ? "bad" : "")) +
    row("tiles", l.tiles) +
    row("disk left", l.disk_free_bytes === null ? "?" :
        (l.disk_free_bytes / 1e9).toFixed(1) + " GB");
  plot(l.autofocus);
}
function plot(a) {
  const svg = document.getElementById("af"), t = a.t_s;
  if (t.length < 2) { svg.innerHTML = ""; return; }
  const v = a.a_y_mps2.concat(a.a_z_mps2), lo = Math.min(...v), hi = Math.max(...v);
  const x = i => 600 * (t[i] - t[0]) / (t[t.length - 1] - t[0] || 1);
  const y = u => 150 - 140 * (u - lo) / (hi - lo || 1);
  const line = (s, col) => "<polyline fill='none' stroke='" + col + "' points='" +
    s.map((u, i) => x(i).toFixed(1) + "," + y(u).toFixed(1)).join(" ") + "'/>";
  svg.innerHTML = line(a.a_y_mps2, "#f55") + line(a.a_z_mps2, "#5dd") +
    "<text x='4' y='12' fill='#aaa' font-size='11'>" + hi.toPrecision(3) + "</text>" +
    "<text x='4' y='156' fill='#aaa' font-size='11'>" + lo.toPrecision(3) + "</text>";
}
function tick() {
  status().catch(() => {});
  document.getElementById("strip").src = "tiles/latest.png?" + Date.now();
}
tick();
setInterval(tick, @POLL_MS@);
</script></body></html>
""".replace("@POLL_MS@", str(round(LIVE_PAGE_POLL_S * 1000))).replace(
    "__LIVE_LEVELS__", json.dumps(level_names())
)
"""``GET /``: the operator's live page (no external assets; data from /status, /live.json;
the live image's degraded level, :mod:`sarmoco.daemon.livelevel`, in words)."""


class StatusServer:
    """HTTP status endpoint on the loopback interface, served from a daemon thread.

    Parameters
    ----------
    counters : Counters
        The registry to publish.
    health : Health
        The component states to publish.
    host : str
        ``127.0.0.1`` (default), ``::1`` or ``localhost``; anything else is refused.
    port : int
        TCP port; 0 picks a free one (see :attr:`port`).
    request_timeout_s : float
        A connection that sends no complete request for this long is closed, s.
    live : LiveView, optional
        Serve the live page from this run's store (None: ``/`` is 404).

    Raises
    ------
    ConfigError
        ``host`` is not a loopback address.
    """

    def __init__(
        self,
        counters: Counters,
        health: Health,
        host: str = "127.0.0.1",
        port: int = 0,
        request_timeout_s: float = REQUEST_TIMEOUT_S,
        live: LiveView | None = None,
    ) -> None:
        if host not in STATUS_HOSTS:
            raise ConfigError(f"status.host: {host!r} is not one of {', '.join(STATUS_HOSTS)}")
        self.counters = counters
        self.health = health
        self.live = live
        self._started = time.monotonic()
        server_class = _V6Server if host == "::1" else _Server
        self._server = server_class((host, port), _handler_for(self, request_timeout_s))
        self._thread = threading.Thread(
            target=self._server.serve_forever, name="sarmoco-status", daemon=True
        )

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self._server.server_address[1])

    def start(self) -> StatusServer:
        """Start serving in the background; returns self."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close the socket."""
        if self._thread.is_alive():
            self._server.shutdown()
            self._thread.join()
        self._server.server_close()

    def status(self) -> dict[str, Any]:
        """The ``/status`` document."""
        snap = self.counters.snapshot()
        return {
            "healthy": self.health.healthy,
            "uptime_s": round(time.monotonic() - self._started, 3),
            "components": self.health.components(),
            "counters": snap["counters"],
            "gauges": snap["gauges"],
        }


class _Server(ThreadingHTTPServer):
    request_queue_size = 128  # connections waiting to be accepted (5 would turn a burst away)


class _V6Server(_Server):
    address_family = socket.AF_INET6


def _handler_for(server: StatusServer, timeout_s: float) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        timeout = timeout_s  # the socket's: a stalled request ends the connection

        def __getattr__(self, name: str) -> Any:
            """``do_<METHOD>`` of every method but GET: 405 (the endpoint is read-only)."""
            if name.startswith("do_"):
                return self._not_allowed
            raise AttributeError(name)

        def _not_allowed(self) -> None:
            self.send_response(405)
            self.send_header("Allow", "GET")
            self.send_header("Content-Length", "0")
            self.end_headers()

        def do_GET(self) -> None:
            try:
                code, ctype, body = self._answer(self.path.split("?", 1)[0])
            except Exception as exc:  # a request must never reset the connection
                log.exception("status: %s failed", self.path)
                code, ctype, body = 500, "text/plain", f"internal error: {exc}\n".encode()
            self._send(code, ctype, body)

        def _answer(self, path: str) -> tuple[int, str, bytes]:
            """Status code, content type and body of the answer to GET ``path``."""
            if path == "/status":
                body, ctype, code = json.dumps(server.status()), "application/json", 200
            elif path == "/metrics":
                body = prometheus_text(server.counters, server.health)
                ctype, code = "text/plain; version=0.0.4", 200
            elif path == "/health":
                bad = {k: v for k, v in server.health.components().items() if not v["ok"]}
                ok = server.health.healthy
                body = "ok\n" if ok else (json.dumps(bad) if bad else "no component reported\n")
                ctype, code = "text/plain", 200 if ok else 503
            elif server.live is not None and path in ("/", "/live.json", "/tiles/latest.png"):
                if path == "/":
                    body, ctype, code = LIVE_PAGE, "text/html", 200
                elif path == "/live.json":
                    body, ctype, code = json.dumps(server.live.summary()), "application/json", 200
                else:
                    png = server.live.png()
                    if png is not None:
                        return 200, "image/png", png
                    body, ctype, code = "no tile yet\n", "text/plain", 404
            else:
                body, ctype, code = "not found\n", "text/plain", 404
            return code, f"{ctype}; charset=utf-8", body.encode()

        def _send(self, code: int, ctype: str, data: bytes) -> None:
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def log_message(self, format: str, *args: Any) -> None:
            """Requests are not logged (scrapes every few seconds would flood the journal)."""

    return Handler
