"""Counters, the loopback HTTP status endpoint, Prometheus text, structured logs."""

from __future__ import annotations

import io
import json
import logging
import os
import re
import signal
import socket
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from sarmoco.daemon import logging_setup
from sarmoco.daemon.navbuffer import NavBuffer
from sarmoco.daemon.status import Counters, Health, StatusServer, metric_name, prometheus_text
from sarmoco.errors import ConfigError


def _get(url: str) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(url, timeout=5) as resp:
            return resp.status, resp.read().decode()
    except urllib.error.HTTPError as err:
        return err.code, err.read().decode()


def test_counters_are_thread_safe() -> None:
    counters = Counters()

    def bump() -> None:
        for _ in range(5000):
            counters.inc("pulses")

    threads = [threading.Thread(target=bump) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert counters.snapshot()["counters"]["pulses"] == 20000


def test_http_status_metrics_health_on_loopback() -> None:
    counters, health = Counters(), Health()
    nav = NavBuffer()
    nav.push_velocity(10, (30.0, 0.0, 0.0))
    nav.push_velocity(10, (30.0, 0.0, 0.0))
    counters.add_source("nav", nav.counts)
    counters.inc("pulses_recorded", 256)
    counters.set("ins_age_s", 0.012)
    health.set("ins", True)
    health.set("radar", False, "no packet for 2.0 s")
    server = StatusServer(counters, health, "127.0.0.1", 0).start()
    try:
        base = f"http://127.0.0.1:{server.port}"
        code, body = _get(base + "/status")
        doc = json.loads(body)
        assert code == 200 and doc["healthy"] is False
        assert doc["counters"]["pulses_recorded"] == 256
        assert doc["counters"]["nav_kinematics_duplicate"] == 1
        assert doc["components"]["radar"] == {"ok": False, "detail": "no packet for 2.0 s"}
        assert _get(base + "/health")[0] == 503
        health.set("radar", True)
        assert _get(base + "/health") == (200, "ok\n")
        code, text = _get(base + "/metrics")
        assert code == 200
        assert "# TYPE sarmoco_pulses_recorded_total counter" in text
        assert "sarmoco_pulses_recorded_total 256\n" in text
        assert "sarmoco_ins_age_s 0.012\n" in text
        assert 'sarmoco_component_up{component="radar"} 1' in text
        sample = re.compile(r"^[a-zA-Z_:][a-zA-Z0-9_:]*(\{[^}]*\})? \S+$")
        for line in text.splitlines():
            assert line.startswith("# TYPE ") or sample.match(line), line
        assert _get(base + "/nothing")[0] == 404
    finally:
        server.stop()


def test_a_failing_counter_source_answers_500_not_a_reset(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A counter source that raises (a thread's state read mid-change) makes /status and
    /metrics answer 500 with the reason, logged; the endpoint goes on answering."""
    counters = Counters()
    failing = {"on": True}

    def source() -> dict[str, float]:
        if failing["on"]:
            raise RuntimeError("dictionary changed size during iteration")
        return {"n": 1.0}

    counters.add_source("flaky", source)
    server = StatusServer(counters, Health(), "127.0.0.1", 0).start()
    try:
        base = f"http://127.0.0.1:{server.port}"
        for path in ("/status", "/metrics"):
            code, body = _get(base + path)
            assert code == 500 and "dictionary changed size" in body, (path, body)
        assert "status: /status failed" in caplog.text
        failing["on"] = False
        code, body = _get(base + "/status")
        assert code == 200 and json.loads(body)["counters"]["flaky_n"] == 1.0
    finally:
        server.stop()


def test_only_loopback_is_served() -> None:
    with pytest.raises(ConfigError):
        StatusServer(Counters(), Health(), "0.0.0.0", 0)
    assert metric_name("kinematics-stale.count") == "kinematics_stale_count"
    assert metric_name("5xx") == "_5xx"
    assert "component_up" in prometheus_text(Counters(), Health())


@pytest.fixture
def restore_logging() -> Iterator[None]:
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield
    logging_setup.setup_logging(stream=io.StringIO())
    for h in list(root.handlers):
        root.removeHandler(h)
        h.close()
    for h in handlers:
        root.addHandler(h)
    root.setLevel(level)


def test_json_and_key_value_lines(restore_logging: None) -> None:
    buf = io.StringIO()
    logging_setup.setup_logging("info", "json", stream=buf)
    log = logging.getLogger("sarmoco.test")
    log.info("block recorded", extra={"pulses": 256, "store": "run.zarr"})
    log.debug("hidden")
    try:
        raise RuntimeError("boom")
    except RuntimeError:
        log.exception("failed")
    lines = buf.getvalue().splitlines()
    assert len(lines) == 2
    first = json.loads(lines[0])
    assert first["msg"] == "block recorded" and first["pulses"] == 256
    assert first["level"] == "info" and first["logger"] == "sarmoco.test"
    assert "RuntimeError: boom" in json.loads(lines[1])["exc"]
    buf = io.StringIO()
    logging_setup.setup_logging("debug", "kv", stream=buf)
    log.warning("ins stale", extra={"age_s": 1.5, "link": "udpin:127.0.0.1:14550"})
    line = buf.getvalue().strip()
    assert "\n" not in line
    assert 'msg="ins stale"' in line and "age_s=1.5" in line and "level=warning" in line


def test_sighup_reopens_the_log_file(tmp_path: Path, restore_logging: None) -> None:
    path = tmp_path / "sarmoco.log"
    logging_setup.setup_logging("info", "kv", path=path)
    previous = signal.getsignal(signal.SIGHUP)
    logging_setup.install_sighup()
    try:
        log = logging.getLogger("sarmoco.test")
        log.info("before rotation")
        path.rename(tmp_path / "sarmoco.log.1")
        os.kill(os.getpid(), signal.SIGHUP)  # handled before the next bytecode runs
        log.info("after rotation")
    finally:
        signal.signal(signal.SIGHUP, previous)
    assert "before rotation" in (tmp_path / "sarmoco.log.1").read_text()
    assert "after rotation" in path.read_text()


def _request(port: int, text: bytes) -> bytes:
    """Send raw bytes to the status port; the whole answer."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(text)
        chunks = []
        while chunk := sock.recv(65536):
            chunks.append(chunk)
    return b"".join(chunks)


def test_methods_other_than_get_are_405() -> None:
    server = StatusServer(Counters(), Health(), "127.0.0.1", 0).start()
    try:
        for method in ("POST", "PUT", "DELETE", "PATCH", "HEAD", "OPTIONS", "BREW"):
            request = f"{method} /status HTTP/1.1\r\nHost: x\r\n\r\n".encode()
            answer = _request(server.port, request)
            assert answer.startswith(b"HTTP/1.0 405 "), (method, answer)
            assert b"\r\nAllow: GET\r\n" in answer
    finally:
        server.stop()


def test_stalled_and_oversized_requests_do_not_stall_the_endpoint() -> None:
    """40 clients that never finish their request: a GET is still answered at once, and
    each stalled connection is closed after the request timeout."""
    server = StatusServer(Counters(), Health(), "127.0.0.1", 0, request_timeout_s=1.0).start()
    t0 = time.monotonic()
    stalled = [socket.create_connection(("127.0.0.1", server.port)) for _ in range(40)]
    try:
        for k, sock in enumerate(stalled):
            sock.sendall(b"GET /sta" if k % 2 else b"GET /status HTTP/1.1\r\nHost:")
        assert _get(f"http://127.0.0.1:{server.port}/health")[0] == 503
        assert time.monotonic() - t0 < 0.5  # no connection waited to be accepted
        answer = _request(server.port, b"GET /status HTTP/1.1\r\nX: " + b"a" * 200_000)
        assert answer.startswith(b"HTTP/1.0 431 ") or answer.startswith(b"HTTP/1.0 400 ")
        stalled[0].settimeout(5.0)
        t0 = time.monotonic()
        assert stalled[0].recv(100) == b""  # closed by the server, unanswered
        assert time.monotonic() - t0 < 1.5
    finally:
        for sock in stalled:
            sock.close()
        server.stop()
