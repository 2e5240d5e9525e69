"""Counters, health and the local status endpoint.

:class:`Counters` is a thread-safe registry that every part of the daemon
increments (or that pulls numbers from the parts' own counters at read time).
:class:`Health` holds one state per component (INS, radar, recorder,
processing). :class:`StatusServer` serves both over HTTP on the loopback
interface only:

- ``GET /status``: JSON ``{"healthy", "uptime_s", "components", "counters", "gauges"}``;
- ``GET /health``: 200 ``ok`` when every component is healthy, else 503 and the failing ones;
- ``GET /metrics``: the same numbers in the Prometheus text format (0.0.4):
  counters as ``sarmoco_<name>_total``, gauges as ``sarmoco_<name>``, health as
  ``sarmoco_component_up{component="..."}``.

The endpoint is read-only: any other method is answered 405. Each connection has its
own thread, and one that does not finish its request within
:data:`REQUEST_TIMEOUT_S` is closed, so a slow or stalled client holds nothing.
"""

from __future__ import annotations

import json
import math
import re
import socket
import threading
import time
from collections.abc import Callable, Mapping
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from sarmoco.errors import ConfigError

LOOPBACK_HOSTS = ("127.0.0.1", "::1", "localhost")
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
        """
        with self._lock:
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
    ) -> None:
        if host not in LOOPBACK_HOSTS:
            raise ConfigError(f"status.host: {host!r} is not one of {', '.join(LOOPBACK_HOSTS)}")
        self.counters = counters
        self.health = health
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
            path = self.path.split("?", 1)[0]
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
            else:
                body, ctype, code = "not found\n", "text/plain", 404
            data = body.encode()
            self.send_response(code)
            self.send_header("Content-Type", f"{ctype}; charset=utf-8")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def log_message(self, format: str, *args: Any) -> None:
            """Requests are not logged (scrapes every few seconds would flood the journal)."""

    return Handler
