"""CPU of the live focusing chain per second of data: full-size pulses through ``Focuser``.

Run as ``python -m bench.bench_live_focuser [--preset ku-vehicle] [--pulses 9000]
[--warm-blocks 12] [--method rda] [--level 0] [--prompt] [--profile]``.

Simulated raw echoes of the full-size preset (turbulent flight, ideal INS, the
preset's targets) go through :class:`~sarmoco.daemon.focuser.Focuser` in blocks of
``imaging.block_pulses`` with their attitude, as the daemon's focusing loop gives them,
with the pre-filter before range compression (``imaging.presum_first``), the autofocus
on and the live level held (``--level``: a level of
:data:`~sarmoco.processing.imaging.rda_tiles.LEVELS`, 0 full resolution; ``--prompt``: each
range-Doppler tile formed alone; what :data:`~sarmoco.daemon.livelevel.LEVEL_COST` and
:data:`~sarmoco.daemon.livelevel.PROMPT_COST` are measured with). Nothing else runs in the
process: no decode, no recording. Process CPU seconds (all threads: numba's and the FFT's pools)
are counted, not wall time, so a machine shared with other work does not skew them.

Printed: CPU per data second of the whole run (the first tiles' filters, the end of the
segment included) and of the steady part (from block ``--warm-blocks`` to the last
push), and the CPU of the segment's end (:meth:`Focuser.finish`: the pulses the
pre-filter and autofocus still hold, the last tiles); of the steady part also the tile
imager's CPU per tile, the rest of the chain's per data second, and how long in data time
each tile waited past its last pulse (the autofocus's release, the block of pulses, the
tiles' own blocks). ``--profile`` adds the functions that took the
most CPU in the steady part (cProfile timed with the process CPU clock).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import time

import numpy as np

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.processing.imaging.rda_tiles import RdaTileImager
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset


class TileClock:
    """CPU seconds spent in the focuser's tile imagers, and the tiles they handed out, while
    :attr:`on` (each imager's ``add`` timed on the instance)."""

    def __init__(self) -> None:
        self.on = False
        self.cpu_s = 0.0
        self.tiles = 0
        self.waits_s: list[float] = []
        """Of each tile formed while on: the last pulse pushed when it came out less the
        tile's last pulse, s of data (what it waited for once its aperture was complete)."""
        self._timed: set[int] = set()

    def watch(self, imager: object) -> None:
        """Time ``imager``'s ``add`` from now on (once per imager)."""
        if id(imager) in self._timed:
            return
        self._timed.add(id(imager))
        add = imager.add  # type: ignore[attr-defined]

        def timed(*args: object, **kwargs: object) -> list[object]:
            c0 = time.process_time()
            out: list[object] = add(*args, **kwargs)
            if self.on:
                self.cpu_s += time.process_time() - c0
                self.tiles += len(out)
            return out

        setattr(imager, "add", timed)  # noqa: B010


def focus_cpu(
    run: SimRun,
    method: str,
    warm_blocks: int,
    profile: bool,
    level: int = 0,
    prompt: bool = False,
    clock: TileClock | None = None,
) -> tuple[float, float, float, float, int, str]:
    """CPU seconds of the whole run, of its steady part and of the segment's end
    (:meth:`Focuser.finish`), the steady part's data seconds, the tiles formed, and
    (``profile``) the steady part's top functions; ``prompt``: range-Doppler tiles formed
    alone; ``clock``: times the tile imagers in the steady part."""
    cfg = scenario_config(
        run.scenario,
        imaging={"method": method, "presum_first": True, "live_degrade": False},
    )
    block = cfg.imaging.block_pulses
    prof = cProfile.Profile(time.process_time) if profile else None
    c0 = time.process_time()
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[:256].mean(axis=0))
    tiles, steady0, first = 0, c0, 0
    for a in range(0, run.t_ns.size, block):
        if a == warm_blocks * block:
            steady0, first = time.process_time(), a
            if prof is not None:
                prof.enable()
            if clock is not None:
                clock.on = True
        b = slice(a, a + block)
        if focuser.segment is not None:
            focuser.segment.tiles.level = level
            if isinstance(focuser.segment.tiles, RdaTileImager):
                focuser.segment.tiles.prompt = prompt
            if clock is not None:
                clock.watch(focuser.segment.imager)
        quat = run.traj.quat[b]
        out = focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b], quat=quat).tiles
        tiles += len(out)
        if clock is not None and clock.on:
            clock.waits_s += [float(run.t_ns[b][-1] - t.t1_ns) * 1e-9 for t in out]
    if prof is not None:
        prof.disable()
    if clock is not None:
        clock.on = False
    end0 = time.process_time()
    steady = end0 - steady0
    tiles += len(focuser.finish().tiles)
    total = time.process_time() - c0
    end = total - (end0 - c0)
    text = ""
    if prof is not None:
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(15)
        text = buf.getvalue()
    return total, steady, end, float(run.t_ns[-1] - run.t_ns[first]) * 1e-9, tiles, text


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="ku-vehicle")
    ap.add_argument("--pulses", type=int, default=9000, help="pulses to simulate and focus")
    ap.add_argument("--warm-blocks", type=int, default=12, help="blocks before the steady part")
    ap.add_argument("--method", default="rda", help="imaging.method (rda, pfa, direct, ffbp)")
    ap.add_argument("--level", type=int, default=0, help="degraded level held (0: full)")
    ap.add_argument("--prompt", action="store_true", help="range-Doppler tiles formed alone")
    ap.add_argument("--profile", action="store_true", help="top functions of the steady part")
    args = ap.parse_args(argv)
    run = simulate(
        load_preset(args.preset, 1.0),
        MotionSpec(kind="turbulence", seed=1),
        "ideal",
        n_pulses=args.pulses,
    )
    data_s = float(run.t_ns[-1] - run.t_ns[0]) * 1e-9
    load = os.getloadavg()[0]
    clock = TileClock()
    total, steady, end, steady_s, tiles, text = focus_cpu(
        run, args.method, args.warm_blocks, args.profile, args.level, args.prompt, clock
    )
    print(f"{args.preset} full size, {run.t_ns.size} pulses ({data_s:.2f} s), {args.method}, "
          f"level {args.level}{', prompt' if args.prompt else ''}, presum first, autofocus on; "
          f"load {load:.1f} on {os.cpu_count()} cores")  # fmt: skip
    print(f"whole run: {total:.2f} CPU s, {total / data_s:.3f} core-s per data second, "
          f"{tiles} tiles")  # fmt: skip
    print(f"steady (from block {args.warm_blocks}, {steady_s:.2f} s of data): {steady:.2f} CPU s, "
          f"{steady / steady_s:.3f} core-s per data second")  # fmt: skip
    print(f"end of the segment (finish): {end:.2f} CPU s")
    if clock.tiles:
        rest = (steady - clock.cpu_s) / steady_s
        per_tile = clock.cpu_s / clock.tiles
        length = scenario_config(run.scenario).imaging.tile_length_m
        tile_rate = float(np.linalg.norm(run.vel_ned.mean(axis=0))) / length
        print(f"steady tile imager: {clock.cpu_s:.2f} CPU s, {clock.tiles} tiles, "
              f"{per_tile:.4f} CPU s per tile; the rest {rest:.3f} core-s per data second; "
              f"at {tile_rate:.2f} tiles per data second: "
              f"{rest + per_tile * tile_rate:.3f} core-s per data second")  # fmt: skip
        waits = np.array(clock.waits_s)
        print(f"steady tiles' wait past their last pulse (data time): min {waits.min():.3f}, "
              f"median {np.median(waits):.3f}, max {waits.max():.3f} s")  # fmt: skip
    if text:
        print(text)


if __name__ == "__main__":
    main()
