"""Shared pieces of the emitter tests: a tiny simulated run and playback helpers."""

from __future__ import annotations

import functools

from sarmoco.sim.emitter import Emitter
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.player import Pacing, PlayResult, play_emitters
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset


@functools.cache
def tiny_run(
    preset: str = "thz-spotlight",
    grade: str = "tactical",
    clock_offset_s: float = 0.0,
    clock_drift_ppm: float = 0.0,
) -> SimRun:
    """A run small enough for a unit test (about 90 pulses of 82 samples, 0.12 s)."""
    scn = load_preset(preset, scale=0.02)
    return simulate(
        scn,
        MotionSpec("turbulence", seed=1),
        grade,
        seed=3,
        ins_clock_offset_s=clock_offset_s,
        ins_clock_drift_ppm=clock_drift_ppm,
    )


def play_fast(*emitters: Emitter, wait_s: float | None = None) -> PlayResult:
    """Play on a virtual clock (the caller reads the links and closes the emitters)."""
    return play_emitters(list(emitters), Pacing(realtime=False), wait_s=wait_s)
