"""Daemon benchmarks: sustained rate of the whole chain, live pulse-to-record latency, RSS.

Run as a plain script (not part of the test suite)::

    .venv/bin/python bench/bench_daemon.py [--work DIR] [--live-s 200] [--profile]

1. **Sustained rate** (``sarmoco replay``): full-size ``thz-spotlight`` pulses (4096
   int16 I/Q samples, PRF 20 kHz) from ``sarmoco sim --out`` files go through the whole
   chain (decode, ring, alignment, range compression, INS compensation, autofocus,
   backprojection, recording) on a virtual clock, as fast as one process can. The rate
   is pulses per wall second over the PRF (1.0 = real time), gross (the command's wall
   time) and net of the interpreter's start-up. ``--profile`` adds a per-stage breakdown
   (cProfile of the same replay in process; nested stages overlap).
2. **Live latency and RSS** (``sarmoco sim --serve`` → ``sarmoco run``, MAVLink/UDP +
   VITA 49/UDP on 127.0.0.1): one long ku-vehicle scale 0.1 run (``--pulses`` for
   ``--live-s`` seconds of flight, a straight track; not a loop of short runs). The
   simulator pins the run to the host clock, so a pulse's GPS time stamp is the host
   GPS time it was due on the wire. The daemon does not publish commit times, so this
   script polls the store's ``pulses/zarr.json`` ``committed`` counter every
   ``POLL_S``: the pulses that became committed between two polls get the later poll's
   host GPS time as their record time (an upper bound, resolution ``POLL_S``). The
   daemon's VmRSS is read from ``/proc/PID/status`` every second.

Everything runs in one process per program on whatever cores the machine has (2 here,
shared with other work): the numbers are for this machine at this load, printed with
the load average.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.app.demo import free_udp_port, read_json_line
from sarmoco.app.simconfig import config_table, write_config
from sarmoco.daemon.config import load_config
from sarmoco.daemon.runner import replay_files
from sarmoco.daemon.store import open_store
from sarmoco.sim.pacing import host_gps_ns
from sarmoco.sim.scenario import load_preset

PY = [sys.executable, "-m", "sarmoco"]
SIM_ARGS = ["--motion", "turbulence", "--motion-seed", "1", "--ins-grade", "tactical"]
LEAP_S = 18
"""GPS - UTC of the simulator's wire and the daemon's default configuration, s."""

POLL_S = 0.01
"""Interval of the committed-counter poll (latency resolution), s."""

LIVE_SCALE = 0.1
START_TIMEOUT_S = 600.0
"""Longest wait for the simulator (it simulates every echo first) or the daemon, s."""

STAGES = {
    "decode (VITA 49 into the ring)": ("pipeline.py", "read_radar"),
    "range compression": ("rangecomp.py", "compress"),
    "INS motion compensation": ("mocomp.py", "compensate"),
    "autofocus push": ("streaming.py", "push"),
    "autofocus flush": ("streaming.py", "flush"),
    "azimuth pre-filter": ("presum.py", "_filter"),
    "tile imager (the next two)": ("tiles.py", "add"),
    "range upsampling (x8)": ("backprojection.py", "upsample"),
    "backprojection kernel": ("backprojection.py", "backproject_into"),
    "recording pulses": ("recorder.py", "append_pulses"),
    "recording image tiles": ("recorder.py", "add_image"),
}
"""Functions whose cumulative time the profile reports: (file name, function name)."""


def load_average() -> str:
    """The 1-minute load average and the core count, for the record."""
    return f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"


def simulate_files(out: Path, preset: str, scale: float) -> Path:
    """``sarmoco sim --out`` files of a preset (reused when present); returns the config."""
    cfg = out / "sarmoco.toml"
    if not cfg.exists():
        subprocess.run(
            [*PY, "sim", "--preset", preset, "--scale", str(scale), *SIM_ARGS, "--out", str(out)],
            check=True, stdout=subprocess.DEVNULL,
        )  # fmt: skip
    return cfg


# -- 1. sustained rate ----------------------------------------------------------------------


@dataclass
class ReplayResult:
    """One ``sarmoco replay`` of the thz-spotlight files."""

    pulses: int
    tiles: int
    wall_s: float
    cpu_s: float
    startup_s: float
    max_rss_mb: float
    prf_hz: float
    n_samples: int

    def ratio(self, net: bool) -> float:
        """Pulses per wall second over the PRF (net: start-up subtracted)."""
        wall = self.wall_s - (self.startup_s if net else 0.0)
        return self.pulses / wall / self.prf_hz


def replay_rate(work: Path, preset: str, scale: float) -> ReplayResult:
    """Time ``sarmoco replay`` of a preset's ``sim --out`` files (one process)."""
    files = work / f"{preset}-{scale:g}"
    cfg_path = simulate_files(files, preset, scale)
    cfg = load_config(cfg_path)
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-c", "import sarmoco.app.cli, sarmoco.daemon.runner"], check=True
    )
    startup = time.perf_counter() - t0
    out = files / f"replay-{time.time_ns()}.zarr"
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [*PY, "replay", "--config", str(cfg_path), "--radar", str(files / "radar.vrt"),
         "--nav", str(files / "nav.tlog"), "--out", str(out), "--quiet"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    _, status, usage = os.wait4(proc.pid, 0)  # this child's own CPU time and peak RSS
    wall = time.perf_counter() - t0
    assert proc.stdout is not None
    stdout = proc.stdout.read()
    proc.stdout.close()
    proc.returncode = os.waitstatus_to_exitcode(status)
    assert proc.returncode == 0, stdout
    m = re.search(r"(\d+) pulses focused, (\d+) tiles", stdout)
    assert m is not None, stdout
    return ReplayResult(
        pulses=int(m.group(1)),
        tiles=int(m.group(2)),
        wall_s=wall,
        cpu_s=usage.ru_utime + usage.ru_stime,
        startup_s=startup,
        max_rss_mb=usage.ru_maxrss / 1024,
        prf_hz=cfg.radar.prf_hz,
        n_samples=cfg.radar.n_samples,
    )


def replay_profile(work: Path) -> dict[str, float]:
    """Cumulative seconds per stage of the same replay, run in this process under cProfile."""
    files = work / "thz-spotlight-1"
    cfg = load_config(simulate_files(files, "thz-spotlight", 1.0))
    out = files / f"profile-{time.time_ns()}.zarr"
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.runcall(replay_files, cfg, files / "radar.vrt", files / "nav.tlog", out, False)
    total = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    times = {"whole replay (in process, profiled)": total}
    for label, (file_name, func) in STAGES.items():
        times[label] = sum(
            v[3] for (f, _, fn), v in stats.items() if f.endswith(file_name) and fn == func
        )
    return times


# -- 2. live latency and RSS ----------------------------------------------------------------


@dataclass
class LiveResult:
    """What a long live run showed."""

    pulses_sent: int
    duration_s: float
    commits: list[tuple[int, int, int]] = field(default_factory=list)
    """(host GPS ns at the poll, committed before, committed after) for each change."""
    rss: list[tuple[float, int]] = field(default_factory=list)
    """(s since the daemon started, VmRSS kB)."""
    status: dict[str, Any] = field(default_factory=dict)
    exit_status: int | None = None
    died_after_s: float | None = None
    """Seconds after start of the last RSS sample when the daemon died before SIGTERM."""
    latency_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    committed: int = 0


def vm_rss_kb(pid: int) -> int:
    """Resident set size of ``pid`` from /proc, kB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for {pid}")


def committed_now(store: Path) -> int:
    """The ``committed`` attribute of the store's pulses (0 before the group exists)."""
    try:
        meta = json.loads((store / "pulses" / "zarr.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return 0
    return int(meta["attributes"]["committed"])


def _watch(pid: int, store: Path, result: LiveResult, stop: threading.Event) -> None:
    """Poll the committed counter every POLL_S and VmRSS every second until ``stop``."""
    t0 = time.monotonic()
    last, next_rss = 0, t0
    while not stop.is_set():
        n = committed_now(store)
        if n > last:
            result.commits.append((host_gps_ns(LEAP_S), last, n))
            last = n
        now = time.monotonic()
        if now >= next_rss:
            try:
                result.rss.append((now - t0, vm_rss_kb(pid)))
            except (FileNotFoundError, RuntimeError):
                return
            next_rss += 1.0
        time.sleep(POLL_S)


def live_run(work: Path, live_s: float, autofocus: bool) -> LiveResult:
    """A long ku-vehicle run from ``sarmoco sim --serve`` into ``sarmoco run``."""
    scn = load_preset("ku-vehicle", LIVE_SCALE)
    n_pulses = round(live_s * scn.radar.prf_hz)
    out = work / f"live-{time.time_ns()}"
    out.mkdir(parents=True)
    sim = subprocess.Popen(
        [*PY, "sim", "--preset", "ku-vehicle", "--scale", str(LIVE_SCALE), "--pulses",
         str(n_pulses), *SIM_ARGS, "--serve", "--radar", f"udp://127.0.0.1:{free_udp_port()}",
         "--ins", f"mavlink:udpout:127.0.0.1:{free_udp_port()}"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    daemon: subprocess.Popen[str] | None = None
    result = LiveResult(pulses_sent=n_pulses, duration_s=n_pulses / scn.radar.prf_hz)
    stop = threading.Event()
    try:
        hello = read_json_line(sim, "the simulator", START_TIMEOUT_S)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            http_port = int(s.getsockname()[1])
        table = config_table(
            scn,
            radar={"link": hello["radar"]["connect"]},
            ins={"protocol": "mavlink", "link": hello["ins"][0]["connect"]},
            recorder={"directory": str(out)},
            status={"http_port": http_port},
            autofocus={"enabled": autofocus},
        )
        cfg_path = write_config(out / "sarmoco.toml", table)
        store = out / "run.zarr"
        with (out / "daemon.log").open("w") as err:
            daemon = subprocess.Popen(
                [*PY, "run", "--config", str(cfg_path), "--store", str(store)],
                stdout=subprocess.PIPE, stderr=err, text=True,
            )  # fmt: skip
        read_json_line(daemon, "the daemon", START_TIMEOUT_S)
        watcher = threading.Thread(target=_watch, args=(daemon.pid, store, result, stop))
        watcher.start()
        sim.wait(timeout=live_s + START_TIMEOUT_S)
        time.sleep(3.0)  # the last pulses wait for INS samples that never come
        stop.set()
        watcher.join()
        if daemon.poll() is None:
            url = f"http://127.0.0.1:{http_port}/status"
            with urllib.request.urlopen(url, timeout=10) as resp:
                result.status = json.loads(resp.read())
            daemon.send_signal(signal.SIGTERM)
        else:  # it died during the run: when is the last RSS sample
            result.died_after_s = result.rss[-1][0] if result.rss else 0.0
        result.exit_status = daemon.wait(timeout=300)
    finally:
        stop.set()
        for proc in (sim, daemon):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    t_ns = open_store(store).read("pulses", ["t_ns"])["t_ns"]
    result.committed = int(t_ns.size)
    lat = [(t_poll - t_ns[a:b]) / 1e9 for t_poll, a, b in result.commits if b <= t_ns.size]
    result.latency_s = np.concatenate(lat) if lat else np.zeros(0)
    return result


def rss_summary(rss: list[tuple[float, int]]) -> dict[str, float]:
    """Median RSS of the first and last minute after a 30 s warm-up, and the trend, MB."""
    t = np.array([r[0] for r in rss])
    mb = np.array([r[1] for r in rss]) / 1024
    warm = t >= 30.0
    t, mb = t[warm], mb[warm]
    if t.size < 10:
        return {}
    first = mb[t < t[0] + 60.0]
    last = mb[t > t[-1] - 60.0]
    slope = float(np.polyfit(t / 60.0, mb, 1)[0])
    return {
        "samples": float(t.size),
        "span_min": float((t[-1] - t[0]) / 60.0),
        "first_min_median_mb": float(np.median(first)),
        "last_min_median_mb": float(np.median(last)),
        "max_mb": float(mb.max()),
        "slope_mb_per_min": slope,
    }


# -- report ---------------------------------------------------------------------------------


def table(rows: list[tuple[str, str]]) -> str:
    """Two aligned columns."""
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{width}}  {v}" for k, v in rows)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--work",
        default=str(Path(tempfile.gettempdir()) / "sarmoco-bench-daemon"),
        help="folder for the simulated files and the stores",
    )
    ap.add_argument("--live-s", type=float, default=200.0, help="live run length, s of flight")
    ap.add_argument("--skip-replay", action="store_true", help="only the live run")
    ap.add_argument("--skip-live", action="store_true", help="only the replay")
    ap.add_argument("--profile", action="store_true", help="per-stage profile of the replay")
    ap.add_argument("--no-autofocus", action="store_true", help="live run without autofocus")
    args = ap.parse_args(argv)
    work = Path(args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    rows: list[tuple[str, str]] = [("machine", load_average() + " (at start)")]
    if not args.skip_replay:
        for preset, scale in (("thz-spotlight", 1.0), ("ku-vehicle", LIVE_SCALE)):
            r = replay_rate(work, preset, scale)
            rows += [
                (f"replay {preset} {scale:g}", f"{r.pulses} pulses x {r.n_samples} I/Q samples, "
                 f"{r.tiles} tiles"),
                ("  wall / CPU", f"{r.wall_s:.1f} s / {r.cpu_s:.1f} s "
                 f"(start-up {r.startup_s:.1f} s)"),
                ("  pulses per second", f"{r.pulses / r.wall_s:.0f} gross, "
                 f"{r.pulses / (r.wall_s - r.startup_s):.0f} net"),
                ("  ratio to real time", f"{r.ratio(False):.4f} gross, {r.ratio(True):.4f} net "
                 f"(PRF {r.prf_hz:g} Hz; single process)"),
                ("  peak RSS", f"{r.max_rss_mb:.0f} MB"),
            ]  # fmt: skip
            print(table(rows[-5:]), flush=True)
        if args.profile:
            prof = replay_profile(work)
            prof_rows = [(f"  {k}", f"{v:.1f} s") for k, v in prof.items()]
            rows += [("replay profile (cumulative)", ""), *prof_rows]
            print(table(prof_rows), flush=True)
    if not args.skip_live:
        lv = live_run(work, args.live_s, not args.no_autofocus)
        lat = lv.latency_s
        c = lv.status.get("counters", {})
        rss = rss_summary(lv.rss)
        rows += [
            ("live ku-vehicle 0.1", f"{lv.pulses_sent} pulses over {lv.duration_s:.0f} s, "
             f"{lv.committed} recorded, exit {lv.exit_status}, autofocus "
             f"{'off' if args.no_autofocus else 'on'}"
             + ("" if lv.died_after_s is None else f", DIED after ~{lv.died_after_s:.0f} s")),
            ("  pipeline counters", f"received {c.get('pipeline_pulses_received', 0):.0f}, "
             f"processed {c.get('pipeline_pulses_processed', 0):.0f}, nav-flagged "
             f"{c.get('pipeline_pulses_nav_flagged', 0):.0f}, ring drops "
             f"{c.get('pipeline_pulses_dropped_ring', 0):.0f}, radar link drops "
             f"{c.get('radar_drops', 0):.0f}, tiles {c.get('pipeline_tiles', 0):.0f}"),
        ]  # fmt: skip
        if lat.size:
            p50, p99 = np.percentile(lat, [50, 99])
            rows.append(
                ("  pulse-to-record latency", f"p50 {p50 * 1e3:.0f} ms, p99 {p99 * 1e3:.0f} ms, "
                 f"max {lat.max() * 1e3:.0f} ms (n {lat.size}, poll {POLL_S * 1e3:.0f} ms)")
            )  # fmt: skip
        if rss:
            flat = abs(rss["last_min_median_mb"] - rss["first_min_median_mb"]) < 20.0
            rows.append(
                ("  RSS (after 30 s)", f"{rss['first_min_median_mb']:.0f} MB first minute, "
                 f"{rss['last_min_median_mb']:.0f} MB last minute, max {rss['max_mb']:.0f} MB, "
                 f"trend {rss['slope_mb_per_min']:+.1f} MB/min over {rss['span_min']:.1f} min "
                 f"-> {'flat' if flat else 'NOT flat'}")
            )  # fmt: skip
        (work / "live_rss.json").write_text(json.dumps(lv.rss))
    rows.append(("machine", load_average() + " (at end)"))
    print("\nbench_daemon results\n" + table(rows))


if __name__ == "__main__":
    main()
