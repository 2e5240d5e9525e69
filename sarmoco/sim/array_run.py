"""One simulated array acquisition and its files (``sarmoco sim --preset mimo-array --out DIR``).

Files, as for the other presets (:mod:`sarmoco.sim.outfiles`):

============  ==================================================================
radar.vrt     VITA 49.2, one stream ID per Tx/Rx pair (:mod:`sarmoco.sim.emit_array`)
nav.tlog      MAVLink 2: LOCAL_POSITION_NED and ATTITUDE_QUATERNION (the roll, as
              measured by the INS grade) at the INS rate, SYSTEM_TIME
truth.json    the scenario, the true DEM (``dem``: heights, spacing, origin), the
              true reference point and roll per pulse, and the ``wire`` section
============  ==================================================================
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.drivers.vita49 import PayloadFormat
from sarmoco.errors import DataFileError
from sarmoco.processing.types import ComplexArray, IntArray
from sarmoco.sim.array_echo import synthesize_array, terrain_scatterers
from sarmoco.sim.array_scenario import ArrayScenario
from sarmoco.sim.emit_array import ArrayRadarEmitter
from sarmoco.sim.emitter import Emitter, WireTime
from sarmoco.sim.faults import Faults
from sarmoco.sim.ins import InsMeasurement, measure_ins
from sarmoco.sim.insclock import InsClock
from sarmoco.sim.insemitters import INS_EMITTERS, InsEmitterOptions
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.outfiles import RADAR_FILE, TRUTH_FILE, write_truth
from sarmoco.sim.player import Pacing, play_emitters
from sarmoco.sim.run import INS_MARGIN_S, pulse_times_ns
from sarmoco.sim.trajectory import Trajectory
from sarmoco.sim.transports import FileLink, Link

NAV_PROTOCOL = "mavlink"
"""The INS recording written for array runs (its file: ``INS_EMITTERS[...].file``)."""


@dataclass(frozen=True)
class ArrayRun:
    """Everything one array simulation produced.

    Parameters
    ----------
    scenario : ArrayScenario
    t_ns : ndarray of int64, shape (P,)
        Pulse transmit times, GPS ns.
    echo : ndarray of complex64, shape (P, C, S)
        Raw samples [pulse, channel, fast time].
    traj : Trajectory
        True kinematics of the reference point at the pulses.
    ins : InsMeasurement
        Simulated navigation samples (the roll as the INS measures it).
    n_scatterers : int
        Scatterers on the terrain.
    """

    scenario: ArrayScenario
    t_ns: IntArray
    echo: ComplexArray
    traj: Trajectory
    ins: InsMeasurement
    n_scatterers: int


def simulate_array(
    scn: ArrayScenario, ins_grade: str = "tactical", ins_rate_hz: float = 200.0, seed: int = 0
) -> ArrayRun:
    """Simulate the echoes of every Tx/Rx pair over the terrain, and the INS.

    Parameters
    ----------
    scn : ArrayScenario
    ins_grade : str
        Key of :data:`sarmoco.sim.ins.GRADES`.
    ins_rate_hz : float
        INS output rate, Hz.
    seed : int
        Seed of the scatterers, the noise and the INS errors.
    """
    t_ns = pulse_times_ns(scn.t0_ns, scn.radar.prf_hz, scn.n_pulses)
    t_s = ((t_ns - scn.t0_ns) * 1e-9).astype(np.float64)
    traj = scn.trajectory(t_s)
    terrain_seed, noise_seed, ins_seed = np.random.SeedSequence(seed).spawn(3)
    terrain = scn.terrain
    targets, amps = terrain_scatterers(
        terrain.height_m,
        terrain.spacing_m,
        terrain.origin_ne_m,
        scn.scatterers_per_cell,
        np.random.default_rng(terrain_seed),
    )
    echo = synthesize_array(
        scn.radar,
        scn.layout,
        traj.pos_ned,
        traj.quat,
        targets,
        amps,
        scn.antenna_length_m,
        scn.max_look_rad,
        scn.snr_db,
        np.random.default_rng(noise_seed),
    )
    ins = measure_ins(
        scn.trajectory,
        float(t_s[0]) - INS_MARGIN_S,
        float(t_s[-1]) + INS_MARGIN_S,
        ins_rate_hz,
        ins_grade,
        seed=int(ins_seed.generate_state(1)[0]),
        epoch_ns=scn.t0_ns,
    )
    return ArrayRun(scn, t_ns, echo, traj, ins, int(amps.size))


def array_ins_feed(run: ArrayRun) -> InsFeed:
    """Every INS sample of the run, on a fault-free device clock."""
    nav, ins = run.ins.nav, run.ins
    clock = InsClock.from_faults(run.scenario.t0_ns, run.scenario.t0_ns, Faults())
    dt = np.diff(ins.t_device_ns)
    return InsFeed(
        index=np.arange(nav.t_ns.size, dtype=np.int64),
        t_ns=nav.t_ns,
        uptime_ns=clock.sample_uptime_ns(ins.t_device_ns, nav.t_ns),
        vel_ned=nav.vel_ned,
        quat=nav.quat,
        pos_ned=nav.pos_ned,
        pulse_t_ns=run.t_ns,
        grade=ins.grade,
        clock=clock,
        rate_hz=1e9 / float(np.median(dt)) if dt.size else 1.0,
    )


def truth_dict(run: ArrayRun) -> dict[str, Any]:
    """JSON-able truth: scenario, true DEM, true reference point and roll per pulse, INS."""
    scn = run.scenario
    roll = scn.roll_rad_at(run.traj.t_s)
    return {
        "scenario": scn.truth_dict() | {"n_scatterers": run.n_scatterers},
        "t0_ns": int(scn.t0_ns),
        "dem": {
            "height_m": scn.terrain.height_m.tolist(),
            "spacing_m": scn.terrain.spacing_m,
            "origin_ne_m": list(scn.terrain.origin_ne_m),
            "frame": "NED north/east of sample [0][0]; heights up from the NED origin's plane",
        },
        "pulses": {
            "t_ns": run.t_ns.tolist(),
            "pos_ned": run.traj.pos_ned.tolist(),
            "roll_rad": roll.tolist(),
        },
        "ins": {"grade": run.ins.grade.name, "n_samples": int(run.ins.nav.t_ns.size)},
    }


def write_array_run(
    run: ArrayRun, out_dir: Path, *, payload: PayloadFormat = "int16", seed: int = 0
) -> dict[str, Any]:
    """Write ``radar.vrt``, ``nav.tlog`` and ``truth.json`` of ``run`` into ``out_dir``.

    Returns
    -------
    dict
        The truth record (also in ``truth.json``), with a ``wire`` section: the wire time
        base and each file's link description and statistics.
    """
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataFileError(f"{out_dir}: cannot create: {exc}") from exc
    feed = array_ins_feed(run)
    radar = array_radar_emitter(run, FileLink(out_dir / RADAR_FILE), payload, seed)
    emitters: dict[str, Emitter] = {"radar": radar}
    nav = INS_EMITTERS[NAV_PROTOCOL]
    emitters[NAV_PROTOCOL] = nav.to_file(
        FileLink(out_dir / nav.file), feed, InsEmitterOptions(None, seed * 16 + 1, 1)
    )
    try:
        result = play_emitters(list(emitters.values()), Pacing(realtime=False))
    finally:
        for e in emitters.values():
            e.close()
    truth = truth_dict(run) | {"wire": wire_section(result.wire, emitters)}
    write_truth(out_dir / TRUTH_FILE, truth)
    return truth


def array_radar_emitter(
    run: ArrayRun, link: Link, payload: PayloadFormat, seed: int
) -> ArrayRadarEmitter:
    """The radar of ``run`` on ``link`` (a file, or a live link): every channel of each
    pulse, one stream per Tx/Rx pair; its noise seeded ``seed * 16``."""
    return ArrayRadarEmitter(
        link, run.scenario.radar, run.t_ns, run.echo, payload=payload, seed=seed * 16, rank=0
    )


def wire_section(wire: WireTime, emitters: Mapping[str, Emitter]) -> dict[str, Any]:
    """The truth record's ``wire`` section: the wire time base (``shift_ns`` added to every
    time on the wire, GPS - UTC) and each link's description and statistics."""
    return {
        "shift_ns": wire.shift_ns,
        "leap_s": wire.leap_s,
        "links": {name: {**e.describe(), "stats": e.stats()} for name, e in emitters.items()},
    }
