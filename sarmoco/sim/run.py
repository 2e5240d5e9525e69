"""One simulated acquisition: pulses, true trajectory, raw echoes, INS samples, truth record."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from sarmoco.processing.types import ComplexArray, FloatArray, IntArray
from sarmoco.sim.echostream import EchoStream, scene_echo
from sarmoco.sim.ins import InsMeasurement, measure_ins
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.scenario import Scenario, radar_table
from sarmoco.sim.trajectory import Trajectory, apc_trajectory, true_trajectory

INS_MARGIN_S = 0.5
"""The INS record starts this long before the first pulse and ends this long after the last, s."""


@dataclass(frozen=True)
class SimRun:
    """Everything one simulation produced (arrays in memory).

    Parameters
    ----------
    scenario : Scenario
    motion : MotionSpec
    t_ns : ndarray of int64, shape (P,)
        Pulse transmit times, GPS ns.
    echo : ndarray of complex64, shape (P, S), or EchoStream
        Raw samples (a stream makes them by blocks when read: long runs).
    apc_ned, vel_ned : ndarray, shape (P, 3)
        True APC position (m) and velocity (m/s) per pulse, NED.
    traj : Trajectory
        True APC kinematics at the pulses (with acceleration and attitude).
    ins : InsMeasurement
        Simulated navigation samples.
    targets_ned : ndarray, shape (K, 3)
    amplitudes : ndarray of complex, shape (K,)
    t0_ns : int
        GPS time of the first pulse, ns.
    """

    scenario: Scenario
    motion: MotionSpec
    t_ns: IntArray
    echo: ComplexArray | EchoStream
    apc_ned: FloatArray
    vel_ned: FloatArray
    traj: Trajectory
    ins: InsMeasurement
    targets_ned: FloatArray
    amplitudes: ComplexArray
    t0_ns: int

    def truth_dict(self) -> dict[str, Any]:
        """JSON-able truth record (scenario, motion, targets, true APC per pulse, INS samples)."""
        scn = self.scenario
        radar = radar_table(scn.radar)
        motion = dataclasses.asdict(self.motion)
        motion["log_path"] = None if self.motion.log_path is None else str(self.motion.log_path)
        nav = self.ins.nav
        return {
            "scenario": {
                "name": scn.name,
                "scale": scn.scale,
                "mode": scn.mode,
                "speed_mps": scn.speed_mps,
                "altitude_m": scn.altitude_m,
                "center_slant_range_m": scn.center_slant_range_m,
                "swath_m": scn.swath_m,
                "aperture_s": scn.aperture_s,
                "integration_angle_rad": scn.integration_angle_rad,
                "scene_center_ned": list(scn.scene_center_ned),
                "heading_rad": scn.heading_rad,
                "look_side": scn.look_side,
                "lever_arm_m": list(scn.lever_arm_m),
                "crab_rad": scn.crab_rad,
                "antenna_squint_rad": scn.antenna_squint_rad,
                "beam_squint_rad": scn.beam_squint_rad,
                "doppler_centroid_hz": scn.doppler_centroid_hz,
                "snr_db": scn.snr_db,
                "clutter_scatterers": 0 if scn.clutter is None else scn.clutter.amplitude.size,
                "radar": radar,
            },
            "motion": motion,
            "t0_ns": int(self.t0_ns),
            "targets": [
                {"pos_ned": p.tolist(), "amplitude": [float(a.real), float(a.imag)]}
                for p, a in zip(self.targets_ned, self.amplitudes, strict=True)
            ],
            "pulses": {
                "t_ns": self.t_ns.tolist(),
                "apc_ned": self.apc_ned.tolist(),
                "vel_ned": self.vel_ned.tolist(),
            },
            "ins": {
                "grade": self.ins.grade.name,
                "t_ns": nav.t_ns.tolist(),
                "t_device_ns": self.ins.t_device_ns.tolist(),
                "vel_ned": nav.vel_ned.tolist(),
                "quat": nav.quat.tolist(),
                "pos_ned": None if nav.pos_ned is None else nav.pos_ned.tolist(),
                "vel_bias_ned": self.ins.vel_bias_ned.tolist(),
            },
        }


def pulse_times_ns(t0_ns: int, prf_hz: float, n_pulses: int) -> IntArray:
    """Uniform pulse transmit times, GPS ns."""
    return t0_ns + np.round(np.arange(n_pulses) * (1e9 / prf_hz)).astype(np.int64)


def simulate(
    scn: Scenario,
    motion: MotionSpec,
    ins_grade: str,
    ins_rate_hz: float = 200.0,
    seed: int = 0,
    n_pulses: int | None = None,
    ins_clock_offset_s: float = 0.0,
    ins_clock_drift_ppm: float = 0.0,
    stream_echo: bool = False,
) -> SimRun:
    """Simulate one acquisition of ``scn`` along the trajectory ``motion``.

    Parameters
    ----------
    scn : Scenario
    motion : MotionSpec
    ins_grade : str
        Key of :data:`sarmoco.sim.ins.GRADES`.
    ins_rate_hz : float
        INS output rate on its own clock, Hz.
    seed : int
        Seed of the thermal noise and the INS errors (the trajectory has its own seed).
    n_pulses : int, optional
        Pulses to simulate; default the whole aperture ``scn.n_pulses``.
    ins_clock_offset_s, ins_clock_drift_ppm : float
        INS clock offset (s) and rate error (ppm) against GPS.
    stream_echo : bool
        Make the echo an :class:`~sarmoco.sim.echostream.EchoStream` (synthesized by
        blocks as it is read; other noise draws) instead of an array.

    Returns
    -------
    SimRun
    """
    n = scn.n_pulses if n_pulses is None else n_pulses
    t_ns = pulse_times_ns(scn.t0_ns, scn.radar.prf_hz, n)
    t_s = ((t_ns - scn.t0_ns) * 1e-9).astype(np.float64)
    traj = apc_trajectory(scn, t_s, motion)
    targets, amps = scn.targets_array()
    noise_seed, ins_seed = np.random.SeedSequence(seed).spawn(2)
    echo: ComplexArray | EchoStream
    if stream_echo:
        echo = EchoStream(scn, t_ns, traj.pos_ned, noise_seed)
    else:
        echo = scene_echo(scn, t_ns, traj.pos_ned, np.random.default_rng(noise_seed))
    ins = measure_ins(
        lambda t: true_trajectory(scn, t, motion),
        float(t_s[0]) - INS_MARGIN_S,
        float(t_s[-1]) + INS_MARGIN_S,
        ins_rate_hz,
        ins_grade,
        ins_clock_offset_s,
        ins_clock_drift_ppm,
        seed=int(ins_seed.generate_state(1)[0]),
        epoch_ns=scn.t0_ns,
    )
    return SimRun(
        scenario=scn,
        motion=motion,
        t_ns=t_ns,
        echo=echo,
        apc_ned=traj.pos_ned,
        vel_ned=traj.vel_ned,
        traj=traj,
        ins=ins,
        targets_ned=targets,
        amplitudes=amps,
        t0_ns=scn.t0_ns,
    )
