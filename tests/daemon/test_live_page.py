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

from PIL import Image as PilImage

from sarmoco.app.simconfig import write_config
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
            # the file links finish (read into the ring) before the tiles are formed: go on
            # until two renderings were seen, or the deadline says they never came
            if "radar: finished" in links and "ins: finished" in links and len(pngs) >= 2:
                break
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
    assert len(pngs) >= 2, f"the tile PNG did not change ({len(pngs)} distinct)"
    for body in pngs:
        picture = PilImage.open(io.BytesIO(body))
        picture.load()
        assert picture.format == "PNG" and picture.size[0] > 10 and picture.size[1] > 10
    assert live["tiles"] >= 2
    assert live["disk_free_bytes"] > 0 and live["disk_total_bytes"] >= live["disk_free_bytes"]
    af = live["autofocus"]
    assert len(af["t_s"]) == len(af["a_y_mps2"]) == len(af["a_z_mps2"]) > 0
    assert status["counters"]["pipeline_pulses_received"] == N_PULSES
    for gauge in ("ins_age_seconds", "echo_backlog_pulses"):
        assert gauge in status["gauges"], gauge
    assert {"links", "ins"} <= set(status["components"])
    share = live["png_render_cpu_s"] / daemon_cpu
    print(
        f"live page: {live['png_renders']} renders, {live['png_render_cpu_s'] * 1e3:.1f} ms "
        f"CPU; daemon {daemon_cpu:.2f} s CPU; share {share:.4%}"
    )
    assert live["png_renders"] >= len(pngs) and share < RENDER_SHARE_MAX
