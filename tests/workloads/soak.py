"""The soak: a long live run with 1 % radar loss and a short INS dropout every minute.

Run as a module (not part of the test suite; it takes the flight's length in wall time)::

    .venv/bin/python -m bench.soak [--minutes 30] [--scale 0.1] [--nice N] [--work DIR]

``sarmoco sim --serve`` flies the ku-vehicle preset (straight track, turbulence, tactical
INS) in real time at the scaled preset's own PRF (every pulse it defines, none thinned)
into ``sarmoco run`` over VITA 49/UDP and MAVLink/UDP on 127.0.0.1, with
``--fault loss=0.01@radar`` and ``--fault ins-dropout=60k:0.2`` for every minute k.
The daemon runs as systemd would start it: ``NOTIFY_SOCKET`` is a real AF_UNIX datagram
socket kept by this script and ``WATCHDOG_USEC`` is the unit's ``WatchdogSec``
(``systemd/sarmoco.service``). ``--nice N`` runs this script (the watchdog listener), the
simulator and the daemon at niceness N (negative: priority over the machine's other work,
as an onboard computer gives its acquisition; needs CAP_SYS_NICE): on a shared machine
whose other load leaves the daemon less CPU than a second of data costs, the soak
otherwise measures the other load.
Measured:

- VmRSS of the daemon every second (``/proc``): medians of the first and last minute
  after a 60 s warm-up, the trend (least squares), the maximum;
- every WATCHDOG=1 arrival: the longest gap against ``WatchdogSec``;
- tiles: every tile index the flown track covers, from the first pulse's footprint to
  the last one's, must be in the store (none missing, none twice);
- pulses: every datagram the simulator did not drop is a committed pulse (the store is
  read back after SIGTERM; late or duplicate arrivals counted by the daemon are
  accounted for), times strictly increasing;
- the load average every minute (the machine is shared).

The result is printed and written to ``DIR/soak.json``; the exit status is 0 only when
every check passed.
"""

from __future__ import annotations

import configparser
import json
import math
import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import zarr

from sarmoco.app.benchcmd import PY, SIM_ARGS, proc_cpu_s, proc_status_kb, rss_trend_mb_per_min
from sarmoco.app.demo import free_udp_port, read_json_line
from sarmoco.app.simconfig import config_table, write_config
from sarmoco.daemon.config import load_config
from sarmoco.errors import SarmocoError
from sarmoco.sim.scenario import load_preset
from sarmoco.store import schema
from sarmoco.store.flags import NAV_UNUSABLE
from sarmoco.store.reader import RunStore, open_store
from tests.daemon.test_daemon_process import NotifyListener, http_get
from tests.daemon.test_faults_wire import wait_idle

UNIT = Path(__file__).resolve().parents[2] / "systemd" / "sarmoco.service"
SIM_START_S = 1800.0
"""Longest wait for the simulator to make the trajectory and INS and open its links, s
(echoes are synthesized as they are sent: :mod:`sarmoco.sim.echostream`)."""
RSS_WARMUP_S = 60.0
"""RSS samples before this (imports, the first tiles, buffers filling) are not trended, s."""


def load_average() -> str:
    """The 1-minute load average and the core count, for the record."""
    return f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"


def unit_watchdog_s(unit: Path = UNIT) -> float:
    """``WatchdogSec`` of the systemd unit, s (plain seconds or ``Ns``)."""
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(unit)
    return float(parser["Service"]["WatchdogSec"].removesuffix("s"))


class Sampler(threading.Thread):
    """VmRSS of ``pid`` every second and the load average every minute, until stopped."""

    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid = pid
        self.rss: list[tuple[float, int]] = []
        """(s since the sampler started, VmRSS kB)."""
        self.load: list[tuple[float, float]] = []
        """(s since the sampler started, 1-minute load average)."""
        self.stop = threading.Event()

    def run(self) -> None:
        t0 = time.monotonic()
        while not self.stop.wait(1.0):
            t = time.monotonic() - t0
            try:
                self.rss.append((t, proc_status_kb(self.pid, "VmRSS")))
            except (FileNotFoundError, SarmocoError):
                return
            if not self.load or t - self.load[-1][0] >= 60.0:
                self.load.append((t, os.getloadavg()[0]))


def rss_summary(rss: list[tuple[float, int]], warmup_s: float = RSS_WARMUP_S) -> dict[str, float]:
    """Medians of the first and last minute after ``warmup_s``, the maximum and the trend
    (least squares), MB."""
    t = np.array([r[0] for r in rss], dtype=np.float64)
    mb = np.array([r[1] for r in rss], dtype=np.float64) / 1024.0
    keep = t >= warmup_s
    if np.count_nonzero(keep) < 10:
        return {}
    t, mb = t[keep], mb[keep]
    return {
        "span_min": float((t[-1] - t[0]) / 60.0),
        "first_min_median_mb": float(np.median(mb[t < t[0] + 60.0])),
        "last_min_median_mb": float(np.median(mb[t > t[-1] - 60.0])),
        "max_mb": float(mb.max()),
        "slope_mb_per_min": rss_trend_mb_per_min(rss, warmup_s),
    }


def check_tiles(store: RunStore, tile_length_m: float) -> dict[str, Any]:
    """Tiles recorded against the tiles each segment's track covers.

    Each segment (a ``reference_track`` attribute) numbers its tiles along its own
    track from its start; within a segment every index from the first to the last must
    be recorded once (a missing index is a tile the flown track covered and the daemon
    did not produce).
    """
    segments: dict[str, list[int]] = {}
    for k in range(store.n_images):
        tile = store.path / schema.IMAGES_GROUP / schema.tile_name(k)
        attrs = zarr.open_group(str(tile), mode="r").attrs
        track = json.dumps(attrs.get("reference_track"), sort_keys=True)
        ax0 = float(np.asarray(zarr.open_array(str(tile / "axis0_m"), mode="r")[:1])[0])
        segments.setdefault(track, []).append(math.floor(ax0 / tile_length_m))
    missing = twice = 0
    for got in segments.values():
        missing += len(set(range(min(got), max(got) + 1)) - set(got))
        twice += len(got) - len(set(got))
    return {
        "tiles": store.n_images,
        "segments": len(segments),
        "missing_within_segments": missing,
        "twice": twice,
        "tile_length_m": tile_length_m,
    }


def soak(
    work: Path,
    minutes: float,
    scale: float,
    loss: float,
    dropout_s: float,
    nice: int = 0,
    *,
    dropout_every_s: float = 60.0,
    watchdog_s: float | None = None,
    rss_warmup_s: float = RSS_WARMUP_S,
) -> dict[str, Any]:
    """Run the soak in ``work`` (this process, the simulator and the daemon at niceness
    ``nice``); returns the measured record.

    An INS dropout of ``dropout_s`` starts every ``dropout_every_s``; ``watchdog_s`` is
    the daemon's ``WATCHDOG_USEC`` (default the unit's ``WatchdogSec``); RSS is trended
    after ``rss_warmup_s`` (short runs: ``tests/daemon/test_soak_short.py``).
    """
    os.setpriority(os.PRIO_PROCESS, 0, nice)  # the children inherit it
    scn = load_preset("ku-vehicle", scale)
    n_pulses = round(minutes * 60.0 * scn.radar.prf_hz)
    watchdog_s = unit_watchdog_s() if watchdog_s is None else watchdog_s
    faults = [f"loss={loss}@radar"] + [
        f"ins-dropout={dropout_every_s * k}:{dropout_s}"
        for k in range(1, math.ceil(minutes * 60.0 / dropout_every_s))
    ]
    record: dict[str, Any] = {
        "command": f"python -m bench.soak --minutes {minutes:g} --scale {scale:g} --nice {nice}",
        "nice": nice,
        "pulses_sent": n_pulses,
        "prf_hz": scn.radar.prf_hz,
        "n_samples": scn.radar.n_samples,
        "faults": faults,
        "watchdog_s": watchdog_s,
        "load_at_start": load_average(),
    }
    truth = work / "truth.json"
    sim = subprocess.Popen(
        [*PY, "sim", "--preset", "ku-vehicle", "--scale", str(scale), "--pulses",
         str(n_pulses), *SIM_ARGS, "--serve", "--radar", f"udp://127.0.0.1:{free_udp_port()}",
         "--ins", f"mavlink:udpout:127.0.0.1:{free_udp_port()}", "--truth", str(truth),
         *(f"--fault={f}" for f in faults)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    notify = NotifyListener(work / "notify.sock")
    daemon: subprocess.Popen[str] | None = None
    sampler: Sampler | None = None
    store = work / "run.zarr"
    try:
        t_sim = time.monotonic()
        hello = read_json_line(sim, "the simulator", SIM_START_S)
        record["sim_start_s"] = round(time.monotonic() - t_sim, 1)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            http_port = int(s.getsockname()[1])
        table = config_table(
            scn,
            radar={"link": hello["radar"]["connect"]},
            ins={"protocol": "mavlink", "link": hello["ins"][0]["connect"]},
            recorder={"directory": str(work)},
            status={"http_port": http_port},
        )
        cfg_path = write_config(work / "sarmoco.toml", table)
        env = notify.env(round(watchdog_s * 1e6))
        with (work / "daemon.log").open("w") as err:
            daemon = subprocess.Popen(
                [*PY, "run", "--config", str(cfg_path), "--store", str(store)],
                stdout=subprocess.PIPE, stderr=err, text=True, env=env,
            )  # fmt: skip
        read_json_line(daemon, "the daemon", 120.0)
        t_daemon = notify.now()
        sampler = Sampler(daemon.pid)
        sampler.start()
        sim.wait(timeout=minutes * 60.0 + SIM_START_S)
        status = wait_idle(http_port, timeout_s=600.0)
        record["metrics_page_bytes"] = len(http_get(http_port, "/metrics")[1])
        record["status"] = {k: status[k] for k in ("counters", "gauges") if k in status}
        record["health"] = status.get("components")
        record["alive_at_end"] = daemon.poll() is None
        record["daemon_cpu_s"] = proc_cpu_s(daemon.pid)  # its whole life, start-up included
        t_term = notify.now()
        daemon.send_signal(signal.SIGTERM)
        record["exit_status"] = daemon.wait(timeout=300)
    finally:
        if sampler is not None:
            sampler.stop.set()
            sampler.join()
        notify.close()
        for proc in (sim, daemon):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    pings = np.array(notify.pings())
    gaps = np.diff(np.concatenate([[t_daemon], pings[pings < t_term], [t_term]]))
    record["watchdog"] = {
        "pings": int(pings.size),
        "max_gap_s": float(gaps.max()),
        "expected_pings_at_half_period": int((t_term - t_daemon) / (watchdog_s / 2)),
        "missed": int(np.count_nonzero(gaps >= watchdog_s)),
        "longest_gaps": [
            {"after_s": round(float(t), 2), "gap_s": round(float(g), 2)}
            for t, g in sorted(
                zip(np.concatenate([[t_daemon], pings]), gaps, strict=False), key=lambda tg: -tg[1]
            )[:5]
        ],
        "t_ready_s": round(t_daemon, 2),
        "t_term_s": round(t_term, 2),
    }
    assert sampler is not None
    record["rss"] = rss_summary(sampler.rss, rss_warmup_s)
    record["load_per_minute"] = [round(v, 2) for _, v in sampler.load]
    record["load_at_end"] = load_average()
    run = open_store(store)
    got = run.read("pulses", ["t_ns", "flags"])
    truth_record = json.loads(truth.read_text())
    wire = truth_record["wire"]
    sent_t = np.asarray(truth_record["pulses"]["t_ns"], dtype=np.int64) + int(wire["shift_ns"])
    lost = int(wire["links"]["radar"]["stats"]["faults"]["lost"])  # data and context packets
    metrics = run.attrs["metrics"]
    p = {
        "sent": n_pulses,
        "lost_on_wire_packets": lost,
        "committed": int(got["t_ns"].size),
        "ring_dropped": int(metrics.get("pulses_dropped_ring", 0)),
        "late_dropped": int(metrics.get("pulses_late_dropped", 0)),
        "nav_flagged": int(np.count_nonzero(got["flags"] & np.uint32(NAV_UNUSABLE))),
        "strictly_increasing": bool((np.diff(got["t_ns"]) > 0).all()),
        "all_sent_times": bool(np.isin(got["t_ns"], sent_t).all()),
        "complete": bool(run.attrs["complete"]),
    }
    p["missing_not_lost_on_wire"] = max(
        0, n_pulses - p["committed"] - p["ring_dropped"] - p["late_dropped"] - lost
    )
    record["pulses"] = p
    record["tiles"] = check_tiles(run, load_config(cfg_path).imaging.tile_length_m)
    rss = record["rss"]
    record["checks"] = {
        "exit_0": record["exit_status"] == 0 and record["alive_at_end"],
        "rss_flat": bool(rss) and abs(rss["slope_mb_per_min"]) * rss["span_min"] < 20.0,
        "no_missed_watchdog": record["watchdog"]["missed"] == 0,
        "tiles_complete": record["tiles"]["missing_within_segments"] == 0
        and record["tiles"]["twice"] == 0,
        "no_pulse_lost_in_the_daemon": p["ring_dropped"] + p["late_dropped"] == 0
        and p["missing_not_lost_on_wire"] == 0,
        "store_consistent": p["strictly_increasing"] and p["all_sent_times"] and p["complete"],
    }
    return record
