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
2. **Live latency and RSS**: ``sarmoco bench`` (:mod:`sarmoco.app.benchcmd`: ``sarmoco
   sim --serve`` → ``sarmoco run``, MAVLink/UDP + VITA 49/UDP on 127.0.0.1) of one long
   ku-vehicle scale 0.1 run (``--live-s`` seconds of flight, a straight track; not a
   loop of short runs): its figures (real-time ratio, FFT floor ratio, pulse-to-record
   latency, losses, RSS) and the pipeline's counters.

Everything runs in one process per program on whatever cores the machine has (2 here,
shared with other work): the numbers are for this machine at this load, printed with
the load average.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from sarmoco.app.benchcmd import KEYS, PY, SIM_ARGS, bench
from sarmoco.daemon.config import load_config
from sarmoco.daemon.runner import replay_files
from tests.workloads.soak import load_average

LIVE_SCALE = 0.1
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
        lv = bench(
            "ku-vehicle", args.live_s, scale=LIVE_SCALE, autofocus=not args.no_autofocus, work=work
        )
        rows += [
            (f"live ku-vehicle {LIVE_SCALE:g} (sarmoco bench)", f"{lv['pulses_sent']} pulses "
             f"over {lv['duration_s']:.0f} s, {lv['pulses_recorded']} recorded, exit "
             f"{lv['exit_status']}, autofocus {'off' if args.no_autofocus else 'on'}"),
            *((f"  {k}", f"{lv[k]:.4g}") for k in KEYS),
            ("  pipeline counters", f"taken {lv['pulses_taken']}, focused {lv['pulses_focused']}, "
             f"ring drops {lv['pulses_dropped_ring']}, radar link drops "
             f"{lv['radar_link_drops']}, tiles {lv['tiles']}"),
        ]  # fmt: skip
    rows.append(("machine", load_average() + " (at end)"))
    print("\nbench_daemon results\n" + table(rows))


if __name__ == "__main__":
    main()
