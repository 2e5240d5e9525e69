"""The operator's live page during a real ``sarmoco run`` (file links read at the pace of
processing, status endpoint on 127.0.0.1), fetched as a browser would, without one.

- ``GET /``: the self-contained HTML page (inline script and style, no external asset).
- ``GET /tiles/latest.png``: a PNG that Pillow decodes, 404 before the first tile, and
  that changes as tiles arrive; rendered at most once a second.
- ``GET /live.json`` and ``GET /status``: the fields the page shows.
- The rendering's CPU time against the daemon's (both measured in the run).
"""

from __future__ import annotations

import io
import json
import os
import socket
import time
import tomllib
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
from PIL import Image as PilImage

from sarmoco.app.simconfig import write_config
from sarmoco.daemon.livefeed import LiveFeed
from sarmoco.daemon.status import LiveView
from sarmoco.processing.types import Image
from sarmoco.store.recorder import Recorder
from tests.daemon.test_daemon_process import Daemon, free_port, simulate_files

N_PULSES = 3000
"""Pulses of the run: enough for a few tiles, formed one after another."""

RENDER_SHARE_MAX = 0.02
"""The live page's rendering may cost at most this share of the daemon's CPU time."""


def get(port: int, path: str) -> tuple[int, str, bytes]:
    """GET http://127.0.0.1:PORT/PATH; (status, content type, body)."""
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as resp:
            return int(resp.status), resp.headers["Content-Type"], resp.read()
    except urllib.error.HTTPError as exc:
        return int(exc.code), exc.headers["Content-Type"], exc.read()


def cpu_s(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far, s."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_live_page_during_a_run(tmp_path: Path) -> None:
    simulate_files(tmp_path, N_PULSES)
    table = tomllib.loads((tmp_path / "sarmoco.toml").read_text())
    port = free_port(socket.SOCK_STREAM)
    table["status"] = {"http_port": port}
    config = write_config(tmp_path / "live.toml", table)
    d = Daemon(config, tmp_path / "run.zarr")
    pngs: list[bytes] = []
    try:
        d.started()
        code, ctype, page = get(port, "/")
        assert code == 200 and ctype.startswith("text/html")
        html = page.decode()
        for needle in ("<script>", "tiles/latest.png", 'fetch("status")', "live.json"):
            assert needle in html, needle
        assert "http://" not in html and "https://" not in html and 'src="/' not in html
        before = get(port, "/tiles/latest.png")
        assert before[0] in (200, 404)
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline:
            code, ctype, body = get(port, "/tiles/latest.png")
            if code == 200:
                assert ctype == "image/png"
                if not pngs or body != pngs[-1]:
                    pngs.append(body)
            status = json.loads(get(port, "/status")[2])
            links = status["components"].get("links", {"detail": ""})["detail"]
            backlog = status["gauges"].get("echo_backlog_pulses", 1)
            if "radar: finished" in links and "ins: finished" in links and pngs and not backlog:
                break  # both files read and every pulse out of the ring (slow on a busy host)
            time.sleep(0.3)
        time.sleep(1.1)  # the last tiles, one render interval later
        code, _, body = get(port, "/tiles/latest.png")
        if code == 200 and (not pngs or body != pngs[-1]):
            pngs.append(body)
        live = json.loads(get(port, "/live.json")[2])
        status = json.loads(get(port, "/status")[2])
        daemon_cpu = cpu_s(d.proc.pid)
        assert d.stop() == 0, d.log.read_text()
    finally:
        d.kill_if_running()
    # a file run forms its tiles faster than one rendering a second: that the strip follows
    # new tiles is tested on a store written tile by tile (below)
    assert pngs, "no tile PNG was served during the run"
    for body in pngs:
        picture = PilImage.open(io.BytesIO(body))
        picture.load()
        assert picture.format == "PNG" and picture.size[0] > 10 and picture.size[1] > 10
    assert live["tiles"] >= 2
    assert live["disk_free_bytes"] > 0 and live["disk_total_bytes"] >= live["disk_free_bytes"]
    af = live["autofocus"]
    assert len(af["t_s"]) == len(af["a_y_mps2"]) == len(af["a_z_mps2"]) > 0
    assert status["counters"]["pipeline_pulses_received"] == N_PULSES
    # file links are read at their own pace: no pulse may leave without navigation because
    # the radar file was read ahead of the INS log (the INS covers every pulse)
    assert status["counters"]["pipeline_pulses_nav_flagged"] == 0
    for gauge in ("ins_age_seconds", "echo_backlog_pulses"):
        assert gauge in status["gauges"], gauge
    assert {"links", "ins"} <= set(status["components"])
    share = live["png_render_cpu_s"] / daemon_cpu
    print(
        f"live page: {live['png_renders']} renders, {live['png_render_cpu_s'] * 1e3:.1f} ms "
        f"CPU; daemon {daemon_cpu:.2f} s CPU; share {share:.4%}"
    )
    assert live["png_renders"] >= len(pngs) and share < RENDER_SHARE_MAX


def test_the_strip_follows_the_tiles_as_they_are_recorded(tmp_path: Path) -> None:
    """A real recorder writing tile by tile: 404-free PNG once a tile exists, the same PNG
    while no tile is added, a new one when a tile is, each decodable."""
    path = tmp_path / "run.zarr"
    feed = LiveFeed()
    view = LiveView(path, feed, min_interval_s=0.0)
    assert view.png() is None  # no tile yet
    rng = np.random.default_rng(1)
    with Recorder(path, 8, "int16", config={}, fsync_interval_s=0.0, live=feed) as rec:
        seen = []
        for k in range(3):
            data = (rng.normal(size=(40, 30)) + 1j * rng.normal(size=(40, 30))).astype(np.complex64)
            data[20, 15] = 50.0  # a bright point
            axis0 = 10.0 * k + 0.25 * np.arange(40)
            rec.add_image(Image(data, axis0, 900.0 + 0.2 * np.arange(30), "ground"), k, k + 1)
            png = view.png()
            assert png is not None and (not seen or png != seen[-1])
            assert view.png() == png  # nothing new: the same strip
            seen.append(png)
    for body in seen:
        picture = PilImage.open(io.BytesIO(body))
        picture.load()
        assert picture.format == "PNG"
    assert view.renders == 3
