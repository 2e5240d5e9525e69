"""``sarmoco bench``: can this computer keep up with this radar?

The online chain runs as in flight: ``sarmoco sim --serve`` (a child process) plays a
preset in real time over loopback, VITA 49 over UDP for the radar and MAVLink over UDP
for the INS, into ``sarmoco run`` (another child process) with recording, autofocus
and imaging on, writing into a temporary directory (removed unless ``--keep``). The
simulator pins the run to the host clock, so a pulse's GPS time stamp is the host GPS
time it was due on the wire.

What is measured (one JSON line with ``--json``):

``realtime_ratio``
    Seconds of data focused per wall second of the daemon's focusing loop, over the
    whole stream: pulses focused (``pipeline_pulses_processed``) / PRF over
    ``processing_busy_seconds`` (the wall time the loop spent in focusing passes), both
    from the daemon's ``/status`` at the end of the stream. Above 1 focusing keeps up
    with that margin; below 1 it falls behind and skips ahead (``pulses_focus_skipped``;
    recording goes on: every pulse is stored all the same).
``fft_floor_ratio``
    CPU seconds per pulse taken in of the whole daemon (every thread: decode, ring,
    alignment, focusing, recording; from ``/proc/PID/stat`` between the daemon's ready
    line and the end of the stream) over the CPU seconds per pulse of a single-threaded
    ``scipy.fft.fft`` of the pulse length (rounded up to ``scipy.fft.next_fast_len``, as
    the chain's own FFTs are: 6506 samples, with a prime factor 3253, took 3 times as
    long), timed in this process in the same run.
``cpu_realtime_ratio`` (beside the figures)
    Seconds of data taken in per CPU second of the daemon (all threads): what
    ``realtime_ratio`` would be if the daemon had one core to itself and used only
    it. On a machine shared with other work the wall-time ratio measures the share
    of the cores the daemon got; this one does not.
``live_page_share``
    The operator's live page, watched during the run as its browser does (``/``'s data:
    the tile strip, ``/status`` and ``/live.json`` every :data:`LIVE_PAGE_POLL_S`): the
    CPU time the daemon spent rendering the strip (``png_render_cpu_s`` of
    ``/live.json``) over ``processing_busy_seconds``.
``latency_p50_s``, ``latency_p99_s``
    Pulse to record: the store's ``pulses`` ``committed`` counter is polled every
    :data:`POLL_S`; the pulses that became committed between two polls get the later
    poll's host GPS time as their record time (an upper bound, resolution ``POLL_S``).
``lost_pulses``
    Pulses sent that the store does not hold (radar link drops and ring overflows).
``stage_cpu_us_per_pulse``, ``stage_load``, ``bounding_stage``
    CPU of each stage of the daemon (:mod:`sarmoco.daemon.threadcpu`: ``receive`` socket,
    decode and echo ring; ``record`` ring to store; ``write`` the store's writes;
    ``focus``; ``other``) between the daemon's ready line and the end of the stream, per
    pulse taken in (``focus``: per pulse focused), µs; the load is that times the PRF,
    the cores the stage needs at the radar's rate; the bounding stage is the one with
    the highest load (above 1 it cannot keep up on any number of cores; the ingest
    stages together must also fit beside it).
``tile_latency_p50_s``, ``tile_latency_p99_s``
    Pulse to live tile: the store's ``images`` ``committed`` counter is polled with the
    pulses'; a tile that became committed gets the poll's host GPS time, less the time of
    the first pulse that formed it (its ``t0_ns``: the longest wait of its pulses), over
    the tiles. This includes the synthetic aperture itself.
``tile_latency_last_p50_s``, ``tile_latency_last_p99_s``
    The same from the last pulse that formed the tile (its ``t1_ns``): what the tile
    waited for once its aperture was complete (the blocks of tiles formed together, the
    stages' delays, the focus backlog, the forming and storing).
``peak_rss_mb``, ``rss_growth_mb_per_min``, ``rss_mb_start``, ``rss_mb_middle``, ``rss_mb_end``
    The daemon's peak VmHWM, and the slope of a line fitted to its VmRSS (sampled every
    second) after a warm-up of a third of the stream (30 s at most); VmRSS at the first
    sample after the ready line, at the middle of the stream and at its end.

The simulator renders every pulse's wire samples into a file of the run folder before
it plays (``sarmoco sim --pregenerate``: 16 kB per full-size ``thz-spotlight`` pulse,
26 kB per ``ku-vehicle`` pulse), so that playing only sends: synthesising the echoes as
they are played made it fall behind the radar's clock on a loaded machine, and its INS
then came late. ``--duration`` is bounded by that file's room on the disk.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
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
import scipy.fft

from sarmoco.app.demo import free_udp_port, read_json_line
from sarmoco.app.simconfig import loopback_config, scenario_config
from sarmoco.daemon.config import live_imaging
from sarmoco.daemon.livelevel import level_names
from sarmoco.daemon.status import LIVE_PAGE_POLL_S
from sarmoco.daemon.threadcpu import STAGES
from sarmoco.drivers.clock import GPS_LEAP_SECONDS_DEFAULT
from sarmoco.errors import ConfigError, SarmocoError
from sarmoco.sim.pacing import host_gps_ns
from sarmoco.sim.scenario import PRESETS, load_preset
from sarmoco.store.reader import open_store

PY = [sys.executable, "-m", "sarmoco"]
SIM_ARGS = ["--motion", "turbulence", "--motion-seed", "1", "--ins-grade", "tactical"]
"""The simulated flight: turbulent motion, tactical-grade INS (as the end-to-end tests)."""

POLL_S = 0.01
"""Interval of the committed-counter poll (latency resolution), s."""

START_TIMEOUT_S = 900.0
"""Longest wait for the simulator (it synthesises every echo first) or the daemon, s."""

DRAIN_S = 60.0
"""After the simulator is done, the daemon is stopped once it has recorded every pulse sent,
or when no pulse was recorded for this long, s."""

RSS_WARMUP_MAX_S = 30.0
"""Longest warm-up left out of the RSS trend, s."""

LIVE_PAGE_PATHS = ("/tiles/latest.png", "/status", "/live.json")
"""What the live page fetches at each refresh."""

KEYS = (
    "realtime_ratio",
    "fft_floor_ratio",
    "latency_p50_s",
    "latency_p99_s",
    "tile_latency_p50_s",
    "tile_latency_p99_s",
    "tile_latency_last_p50_s",
    "tile_latency_last_p99_s",
    "lost_pulses",
    "peak_rss_mb",
    "rss_growth_mb_per_min",
    "rss_mb_start",
    "rss_mb_middle",
    "rss_mb_end",
    "live_page_share",
)
"""The figures ``sarmoco bench`` prints (``--json``: with the run's description)."""


# -- the daemon process, seen from outside ---------------------------------------------------


def proc_status_kb(pid: int, field_name: str) -> int:
    """A ``kB`` field of ``/proc/PID/status`` (``VmRSS``, ``VmHWM``), kB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field_name}:"):
            return int(line.split()[1])
    raise SarmocoError(f"bench: no {field_name} for process {pid}")


def proc_cpu_s(pid: int) -> float:
    """User + system CPU time of process ``pid`` (all its threads) so far, s."""
    stat = Path(f"/proc/{pid}/stat").read_text()
    fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def committed_now(store: Path, group: str = "pulses") -> int:
    """The ``committed`` attribute of a group of the store (0 before the group exists)."""
    try:
        meta = json.loads((store / group / "zarr.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return 0
    return int(meta["attributes"]["committed"])


@dataclass
class Watch:
    """What the watcher thread saw of a running daemon."""

    commits: list[tuple[int, int, int]] = field(default_factory=list)
    """(host GPS ns at the poll, committed before, committed after) for each change."""
    rss: list[tuple[float, int]] = field(default_factory=list)
    """(s since the watch began, VmRSS kB)."""
    last_commit_mono: float = 0.0
    """Host monotonic time of the last change of the committed counter, s."""
    tiles: list[tuple[int, int, int]] = field(default_factory=list)
    """(host GPS ns at the poll, tiles committed before, after) for each change."""

    def committed(self) -> int:
        """Pulses committed at the last poll that saw a change."""
        return self.commits[-1][2] if self.commits else 0


def watch(pid: int, store: Path, seen: Watch, stop: threading.Event) -> None:
    """Poll the committed counter every :data:`POLL_S` and VmRSS every second until ``stop``."""
    t0 = time.monotonic()
    last, tiles, next_rss = 0, 0, t0
    while not stop.is_set():
        n = committed_now(store)
        if n > last:
            seen.commits.append((host_gps_ns(GPS_LEAP_SECONDS_DEFAULT), last, n))
            seen.last_commit_mono = time.monotonic()
            last = n
        k = committed_now(store, "images")
        if k > tiles:
            seen.tiles.append((host_gps_ns(GPS_LEAP_SECONDS_DEFAULT), tiles, k))
            tiles = k
        now = time.monotonic()
        if now >= next_rss:
            try:
                seen.rss.append((now - t0, proc_status_kb(pid, "VmRSS")))
            except (FileNotFoundError, SarmocoError):
                return
            next_rss += 1.0
        time.sleep(POLL_S)


def latencies_s(commits: list[tuple[int, int, int]], t_ns: np.ndarray) -> np.ndarray:
    """Pulse-to-record latency of every committed pulse seen by :func:`watch`, s."""
    lat = [(t_poll - t_ns[a:b]) / 1e9 for t_poll, a, b in commits if b <= t_ns.size]
    return np.concatenate(lat) if lat else np.zeros(0)


def tile_pulse_times_ns(store: Path, n_tiles: int) -> np.ndarray:
    """The ``t0_ns`` and ``t1_ns`` attributes (first and last pulse, GPS ns) of the store's
    first ``n_tiles`` tiles, shape (n_tiles, 2)."""
    times = []
    for i in range(n_tiles):
        meta = json.loads((store / "images" / f"tile_{i:06d}" / "zarr.json").read_text())
        times.append((int(meta["attributes"]["t0_ns"]), int(meta["attributes"]["t1_ns"])))
    return np.array(times, dtype=np.int64).reshape(-1, 2)


def tile_latencies_s(tiles: list[tuple[int, int, int]], pulse_ns: np.ndarray) -> np.ndarray:
    """Pulse-to-tile latency of every tile committed while :func:`watch` polled: the poll's
    time less a pulse time of the tile ``pulse_ns`` (GPS ns, by tile), s."""
    lat = [(t_poll - pulse_ns[a:b]) / 1e9 for t_poll, a, b in tiles if b <= pulse_ns.size]
    return np.concatenate(lat) if lat else np.zeros(0)


def rss_at_mb(rss: list[tuple[float, int]], fraction: float) -> float:
    """VmRSS at ``fraction`` (0: first, 1: last) of the samples, MB (NaN: none)."""
    if not rss:
        return float("nan")
    return rss[round(fraction * (len(rss) - 1))][1] / 1024.0


def rss_trend_mb_per_min(rss: list[tuple[float, int]], warmup_s: float) -> float:
    """Slope of a line through the RSS samples after ``warmup_s``, MB/min (NaN: < 3 samples)."""
    t = np.array([r[0] for r in rss], dtype=np.float64)
    mb = np.array([r[1] for r in rss], dtype=np.float64) / 1024.0
    keep = t >= warmup_s
    if np.count_nonzero(keep) < 3:
        return float("nan")
    return float(np.polyfit(t[keep] / 60.0, mb[keep], 1)[0])


def fft_cpu_s_per_pulse(n_samples: int, repeats: int = 20, block: int = 64) -> float:
    """CPU seconds of one single-threaded ``scipy.fft.fft`` of ``n_samples`` complex64
    (zero-padded to ``next_fast_len``), s.

    A block of pulses is transformed along fast time ``repeats`` times (after one
    warm-up call); the best repetition counts (the floor, as other load only adds).
    """
    rng = np.random.default_rng(0)
    x = rng.standard_normal((block, n_samples)) + 1j * rng.standard_normal((block, n_samples))
    x = x.astype(np.complex64)
    n_fft = scipy.fft.next_fast_len(n_samples)
    scipy.fft.fft(x, n_fft, axis=1, workers=1)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        scipy.fft.fft(x, n_fft, axis=1, workers=1)
        best = min(best, time.process_time() - t0)
    return best / block


def dir_bytes(path: Path) -> int:
    """Bytes of all files under ``path``."""
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


# -- one bench run -----------------------------------------------------------------------------


@dataclass
class BenchRun:
    """A simulator → daemon run on loopback and what was seen of it."""

    preset: str
    scale: float
    duration_s: float
    prf_hz: float
    n_samples: int
    pulses_sent: int
    watch: Watch
    status: dict[str, Any]
    """The daemon's ``/status`` document at the end of the stream (before SIGTERM)."""
    status_ready: dict[str, Any]
    """The daemon's ``/status`` document at its ready line."""
    cpu_s: float
    """Daemon CPU seconds from its ready line to the end of the stream."""
    peak_rss_kb: int
    exit_status: int
    store: Path
    t_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    """Times of the recorded pulses, GPS ns."""
    tile_pulse_ns: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    """First and last pulse time of each tile seen committed, GPS ns, shape (tiles, 2)."""
    live: dict[str, Any] = field(default_factory=dict)
    """The daemon's ``/live.json`` at the end of the stream (the live page's rendering)."""

    @property
    def counters(self) -> dict[str, float]:
        """The daemon's counters at the end of the stream."""
        counters: dict[str, float] = self.status.get("counters", {})
        return counters


def _http_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def watch_live_page(port: int, stop: threading.Event) -> None:
    """Fetch what the live page fetches, every :data:`LIVE_PAGE_POLL_S`, until ``stop``."""
    while not stop.wait(LIVE_PAGE_POLL_S):
        for path in LIVE_PAGE_PATHS:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as r:
                    r.read()
            except OSError:  # 404 before the first tile; the daemon busy or stopping
                pass


def _fetch_status(port: int, path: str = "/status") -> dict[str, Any]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as resp:
        status: dict[str, Any] = json.loads(resp.read())
    return status


def _drain(daemon: subprocess.Popen[str], seen: Watch, n_pulses: int, out: Path) -> None:
    """Wait while the daemon records what it still holds: until every one of ``n_pulses`` is
    committed or none was for ``DRAIN_S``; a daemon that died raises :class:`SarmocoError`."""
    while (
        daemon.poll() is None
        and seen.committed() < n_pulses
        and time.monotonic() - seen.last_commit_mono < DRAIN_S
    ):
        time.sleep(0.1)
    if daemon.poll() is not None:
        raise SarmocoError(f"bench: the daemon died (status {daemon.returncode}), see {out}")


def live_run(
    out: Path,
    preset: str,
    scale: float,
    duration_s: float,
    **sections: dict[str, Any],
) -> BenchRun:
    """Play ``duration_s`` of a preset from ``sarmoco sim --serve`` into ``sarmoco run``.

    Parameters
    ----------
    out : Path
        Folder for the configuration, the daemon's log and the store ``run.zarr``.
    preset, scale : str, float
        Scenario (``sarmoco sim --preset --scale``).
    duration_s : float
        Seconds of flight to play (pulses at the scenario's PRF).
    **sections : dict
        Configuration keys per section on top of the scenario's (e.g.
        ``recorder={"raw_echoes": False}``).
    """
    scn = load_preset(preset, scale)
    n_pulses = max(1, round(duration_s * scn.radar.prf_hz))
    sim = subprocess.Popen(
        [*PY, "sim", "--preset", preset, "--scale", str(scale), "--pulses", str(n_pulses),
         *SIM_ARGS, "--serve", "--pregenerate", str(out / "wire.npy"),
         "--radar", f"udp://127.0.0.1:{free_udp_port()}",
         "--ins", f"mavlink:udpout:127.0.0.1:{free_udp_port()}"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    daemon: subprocess.Popen[str] | None = None
    stop = threading.Event()
    seen = Watch()
    store = out / "run.zarr"
    try:
        hello = read_json_line(sim, "the simulator", START_TIMEOUT_S)
        http_port = _http_port()
        cfg_path = loopback_config(
            out, scn, hello["radar"]["connect"], ("mavlink", hello["ins"][0]["connect"]),
            http_port, sections,
        )  # fmt: skip
        with (out / "daemon.log").open("w") as err:
            daemon = subprocess.Popen(
                [*PY, "run", "--config", str(cfg_path), "--store", str(store)],
                stdout=subprocess.PIPE, stderr=err, text=True,
            )  # fmt: skip
        read_json_line(daemon, "the daemon", START_TIMEOUT_S)
        cpu0 = proc_cpu_s(daemon.pid)
        status_ready = _fetch_status(http_port)
        watcher = threading.Thread(target=watch, args=(daemon.pid, store, seen, stop))
        watcher.start()
        viewer = threading.Thread(target=watch_live_page, args=(http_port, stop))
        viewer.start()
        if sim.wait(timeout=duration_s + START_TIMEOUT_S) != 0:
            raise SarmocoError(f"bench: the simulator failed (status {sim.returncode})")
        _drain(daemon, seen, n_pulses, out)
        status = _fetch_status(http_port)
        live = _fetch_status(http_port, "/live.json")
        cpu_s = proc_cpu_s(daemon.pid) - cpu0
        peak_kb = proc_status_kb(daemon.pid, "VmHWM")
        stop.set()
        watcher.join()
        viewer.join()
        daemon.send_signal(signal.SIGTERM)
        exit_status = daemon.wait(timeout=START_TIMEOUT_S)
    finally:
        stop.set()
        for proc in (sim, daemon):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    return BenchRun(
        preset=preset,
        scale=scale,
        duration_s=n_pulses / scn.radar.prf_hz,
        prf_hz=scn.radar.prf_hz,
        n_samples=scn.radar.n_samples,
        pulses_sent=n_pulses,
        watch=seen,
        status=status,
        status_ready=status_ready,
        cpu_s=cpu_s,
        peak_rss_kb=peak_kb,
        exit_status=exit_status,
        store=store,
        live=live,
        t_ns=open_store(store).read("pulses", ["t_ns"])["t_ns"],
        tile_pulse_ns=tile_pulse_times_ns(store, seen.tiles[-1][2] if seen.tiles else 0),
    )


def stage_figures(run: BenchRun) -> dict[str, Any]:
    """Each stage's CPU per pulse (µs) and load (cores at the PRF), and the bounding
    stage (see the module)."""
    c, c0 = run.counters, run.status_ready.get("counters", {})
    taken = c.get("pipeline_pulses_received", 0.0)
    focused = c.get("pipeline_pulses_processed", 0.0)
    per_pulse = {}
    for stage in STAGES:
        key = f"cpu_seconds_{stage}"
        pulses = focused if stage == "focus" else taken
        cpu = c.get(key, 0.0) - c0.get(key, 0.0)
        per_pulse[stage] = cpu / pulses * 1e6 if pulses else float("nan")
    load = {k: v * 1e-6 * run.prf_hz for k, v in per_pulse.items()}
    chain = {k: v for k, v in load.items() if k != "other" and not np.isnan(v)}
    return {
        "stage_cpu_us_per_pulse": per_pulse,
        "stage_load": load,
        "bounding_stage": max(chain, key=chain.__getitem__) if chain else None,
    }


def figures(run: BenchRun, fft_s_per_pulse: float) -> dict[str, float]:
    """The :data:`KEYS` figures of a run (see the module)."""
    c = run.counters
    taken = c.get("pipeline_pulses_received", 0.0)
    focused = c.get("pipeline_pulses_processed", 0.0)
    busy = c.get("processing_busy_seconds", 0.0)
    lat = latencies_s(run.watch.commits, run.t_ns)
    p50, p99 = np.percentile(lat, [50, 99]) if lat.size else (float("nan"), float("nan"))
    nan2 = (float("nan"), float("nan"))
    tile_lat = tile_latencies_s(run.watch.tiles, run.tile_pulse_ns[:, 0])
    tile_p50, tile_p99 = np.percentile(tile_lat, [50, 99]) if tile_lat.size else nan2
    last_lat = tile_latencies_s(run.watch.tiles, run.tile_pulse_ns[:, 1])
    last_p50, last_p99 = np.percentile(last_lat, [50, 99]) if last_lat.size else nan2
    warmup = min(RSS_WARMUP_MAX_S, run.duration_s / 3.0)
    return {
        "realtime_ratio": focused / run.prf_hz / busy if busy > 0 else float("nan"),
        "fft_floor_ratio": run.cpu_s / taken / fft_s_per_pulse if taken else float("nan"),
        "latency_p50_s": float(p50),
        "latency_p99_s": float(p99),
        "tile_latency_p50_s": float(tile_p50),
        "tile_latency_p99_s": float(tile_p99),
        "tile_latency_last_p50_s": float(last_p50),
        "tile_latency_last_p99_s": float(last_p99),
        "lost_pulses": float(run.pulses_sent - run.t_ns.size),
        "peak_rss_mb": run.peak_rss_kb / 1024.0,
        "rss_growth_mb_per_min": rss_trend_mb_per_min(run.watch.rss, warmup),
        "rss_mb_start": rss_at_mb(run.watch.rss, 0.0),
        "rss_mb_middle": rss_at_mb(run.watch.rss, 0.5),
        "rss_mb_end": rss_at_mb(run.watch.rss, 1.0),
        "live_page_share": run.live.get("png_render_cpu_s", 0.0) / busy
        if busy > 0
        else float("nan"),
    }


def pulse_figures(run: BenchRun) -> dict[str, Any]:
    """The daemon's pulse counters at the end of the stream, its CPU and the live page's
    rendering cost; the tiles formed while the stream played (``tiles_live``) and in all,
    once the daemon stopped (``tiles``: a spotlight's strip closes its tiles at the end)."""
    c = run.counters
    return {
        "pulses_taken": int(c.get("pipeline_pulses_received", 0)),
        "pulses_focused": int(c.get("pipeline_pulses_processed", 0)),
        "pulses_focus_skipped": int(c.get("pipeline_pulses_focus_skipped", 0)),
        "pulses_nav_flagged": int(c.get("pipeline_pulses_nav_flagged", 0)),
        "pulses_dropped_ring": int(c.get("pipeline_pulses_dropped_ring", 0)),
        "radar_link_drops": int(c.get("radar_drops", 0)),
        "tiles_live": int(c.get("pipeline_tiles", 0)),
        "tiles": open_store(run.store).n_images,
        "processing_busy_s": c.get("processing_busy_seconds", 0.0),
        "daemon_cpu_s": run.cpu_s,
        "live_page_renders": int(run.live.get("png_renders", 0)),
        "live_page_cpu_s": run.live.get("png_render_cpu_s", 0.0),
        "cpu_realtime_ratio": c.get("pipeline_pulses_received", 0.0) / run.prf_hz / run.cpu_s
        if run.cpu_s > 0
        else float("nan"),
    }


def live_image_figures(run: BenchRun) -> dict[str, Any]:
    """The live image at the end of the stream: its level (a number and in words) and
    whether its tiles were prompt (None each without a live imager's level rule)."""
    gauges = run.status.get("gauges", {})
    level, prompt = gauges.get("live_image_level"), gauges.get("live_image_prompt")
    return {
        "live_image_level": level,
        "live_image": None if level is None else level_names()[int(level)],
        "live_image_prompt": None if prompt is None else bool(prompt),
    }


def _check_arguments(
    preset: str, scale: float, duration_s: float, min_level: int, live_budget: float | None
) -> None:
    if preset not in PRESETS:
        raise ConfigError(f"bench --preset: {preset!r} is not one of {', '.join(PRESETS)}")
    if not 0.0 < scale <= 1.0:
        raise ConfigError(f"bench --scale: {scale!r} is not in (0, 1]")
    if not duration_s > 0.0:
        raise ConfigError(f"bench --duration: {duration_s!r} s is not > 0")
    if not 0 <= min_level < len(level_names()):
        raise ConfigError(f"bench --min-level: {min_level!r} is not a level of the live image")
    if live_budget is not None and not live_budget > 0.0:
        raise ConfigError(f"bench --live-budget: {live_budget!r} is not > 0")


def _sections(
    record: bool,
    autofocus: bool,
    presum_first: bool,
    method: str | None,
    min_level: int,
    live_budget: float | None = None,
) -> dict[str, dict[str, Any]]:
    """The configuration keys the bench sets on top of the scenario's (see :func:`bench`)."""
    sections: dict[str, dict[str, Any]] = {
        "recorder": {"raw_echoes": record},
        "imaging": {"presum_first": presum_first, "live_min_level": min_level}
        | ({} if method is None else {"method": method, "live_method": "method"})
        | ({} if live_budget is None else {"live_budget": live_budget}),
    }
    if not autofocus:
        sections["autofocus"] = {"enabled": False}
    return sections


def bench(
    preset: str,
    duration_s: float,
    *,
    scale: float = 1.0,
    record: bool = True,
    autofocus: bool = True,
    presum_first: bool = False,
    method: str | None = None,
    min_level: int = 0,
    live_budget: float | None = None,
    work: Path | None = None,
    keep: bool = False,
) -> dict[str, Any]:
    """Run the bench (see the module); returns the figures and the run's description.

    Parameters
    ----------
    preset : str
        Scenario preset (``sarmoco sim --preset``).
    duration_s : float
        Seconds of flight to play.
    scale : float
        Scenario scale in (0, 1].
    record : bool
        Record the raw echoes (``recorder.raw_echoes``).
    autofocus : bool
        Autofocus on (``autofocus.enabled``; the scenario may have it off when its
        aperture holds fewer than two subapertures).
    presum_first : bool
        Pre-filter before range compression (``imaging.presum_first``).
    method : str, optional
        Tile image formation of the live run (``imaging.method``: direct, ffbp, rda or
        pfa, with ``imaging.live_method = "method"``); default: the scenario's
        configuration (``imaging.live_method``: pfa for spotlight; else ``imaging.method``).
    min_level : int
        Lowest degraded level of the live image (``imaging.live_min_level``; 0: full
        resolution).
    live_budget : float, optional
        Share of real time the live imager may spend focusing before it steps up
        (``imaging.live_budget``; default the configuration's): a large one brings the
        rule down to prompt tiles (at ``min_level`` 0) after its first window.
    work : Path, optional
        Where the temporary run folder is made (default: the system's temporary folder).
    keep : bool
        Keep the run folder (store, configuration, daemon log).

    Raises
    ------
    ConfigError
        For an unknown preset, a scale outside (0, 1] or a duration not > 0.
    """
    _check_arguments(preset, scale, duration_s, min_level, live_budget)
    if work is not None:
        work.mkdir(parents=True, exist_ok=True)
    out = Path(tempfile.mkdtemp(prefix=f"sarmoco-bench-{preset}-", dir=work))
    sections = _sections(record, autofocus, presum_first, method, min_level, live_budget)
    load_start = os.getloadavg()[0]
    try:
        fft_s = fft_cpu_s_per_pulse(load_preset(preset, scale).radar.n_samples)
        run = live_run(out, preset, scale, duration_s, **sections)
        written = dir_bytes(run.store)
        counted = pulse_figures(run) | live_image_figures(run)
    finally:
        if not keep:
            shutil.rmtree(out, ignore_errors=True)
    return (
        figures(run, fft_s)
        | stage_figures(run)
        | counted
        | {
            "preset": preset,
            "scale": scale,
            "duration_s": run.duration_s,
            "pulses_sent": run.pulses_sent,
            "pulses_recorded": int(run.t_ns.size),
            "fft_cpu_s_per_pulse": fft_s,
            "record_raw_echoes": record,
            "presum_first": presum_first,
            "method": live_imaging(
                scenario_config(load_preset(preset, scale), **sections)
            ).imaging.method,
            "live_min_level": min_level,
            "bytes_written": written,
            "exit_status": run.exit_status,
            "load_average": [load_start, os.getloadavg()[0]],
            "cores": os.cpu_count(),
            "kept": str(out) if keep else None,
        }
    )


# -- the command -------------------------------------------------------------------------------


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the arguments of ``sarmoco bench`` to its parser."""
    p.description = __doc__.split("\n\n")[0] if __doc__ else None
    p.add_argument("--preset", required=True, choices=PRESETS, help="scenario preset")
    p.add_argument("--duration", type=float, required=True, metavar="S", help="seconds of flight")
    p.add_argument("--scale", type=float, default=1.0, help="scenario scale in (0, 1] (default 1)")
    p.add_argument("--json", action="store_true", help="one JSON line on stdout")
    p.add_argument("--keep", action="store_true", help="keep the run folder (store, log)")
    p.add_argument("--no-record", action="store_true", help="raw echoes not recorded")
    p.add_argument("--no-autofocus", action="store_true", help="autofocus off")
    p.add_argument(
        "--presum-first", action="store_true", help="pre-filter before range compression"
    )
    p.add_argument(
        "--method",
        choices=("direct", "ffbp", "rda", "pfa"),
        help="tile image formation of the live run, imaging.method (default: the scenario's "
        "live imager, imaging.live_method: pfa for spotlight, direct otherwise)",
    )
    p.add_argument(
        "--min-level",
        type=int,
        default=0,
        help="lowest degraded level of the live image, imaging.live_min_level (default 0: "
        "full resolution)",
    )
    p.add_argument(
        "--live-budget",
        type=float,
        metavar="B",
        help="share of real time the live imager may spend focusing before it forms its tiles "
        "in blocks, then degrades, imaging.live_budget (default the configuration's 0.8; a "
        "large one steps down to prompt tiles after the first window)",
    )
    p.add_argument("--work", type=Path, help="folder for the temporary run folder")


def _text(value: Any) -> str:
    """A figure as printed: floats to 4 digits, a dict as ``key value, ...``."""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_text(v)}" for k, v in value.items())
    return str(value)


def run_command(args: argparse.Namespace) -> int:
    """Handler of ``sarmoco bench``; returns the exit status."""
    result = bench(
        args.preset,
        args.duration,
        scale=args.scale,
        record=not args.no_record,
        autofocus=not args.no_autofocus,
        presum_first=args.presum_first,
        method=args.method,
        min_level=args.min_level,
        live_budget=args.live_budget,
        work=args.work,
        keep=args.keep,
    )
    if args.json:
        print(json.dumps(result), flush=True)
        return 0
    width = max(map(len, result))
    for key, value in result.items():
        text = _text(value)
        print(f"{key:<{width}}  {text}")
    where = f"kept in {result['kept']}" if result["kept"] else "removed"
    print(f"{result['bytes_written']} bytes written ({where})")
    return 0
