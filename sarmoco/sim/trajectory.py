"""True APC trajectory: the scenario's straight nominal line plus smooth deviations.

Three kinds (:class:`MotionSpec`):

``ideal``
    The nominal line, level, heading north.
``turbulence``
    Cross-track (east) and vertical (down) displacement, along-track speed variation and
    roll/pitch/yaw each follow an independent seeded Gaussian-like process with the
    one-sided power spectral density of a second-order low-pass (Dryden-like)

        S(f) = S0 / (1 + (f / f_c)**2)**2,   f_c / 20 <= f <= 20 f_c,

    scaled so that its rms is the spec's value (displacement: ``cross_track_rms_m``,
    ``vertical_rms_m``; along-track *speed*: ``along_speed_rms_mps``; each attitude angle:
    ``attitude_rms_rad``). Each process is a sum of ``N_COMPONENTS`` sinusoids at log-spaced,
    randomly jittered frequencies with random phases and amplitudes ``sqrt(2 S(f_m) df_m)``,
    so position, velocity and acceleration are exact analytic derivatives of one smooth
    function, defined for any time (and identical for any sampling of it).
``flightlog``
    Deviations of a real ArduPilot flight from its own straight-line fit: LOCAL_POSITION_NED
    (and ATTITUDE) from a MAVLink telemetry log, rotated so the segment's mean ground track is
    north, detrended (linear fit per axis), and fitted by a cubic smoothing spline whose
    derivatives give velocity and acceleration.

Frames: NED, m, s; ``t_s`` is time since the first pulse. Quaternions are scalar-first and
rotate body to NED (3-2-1 yaw, pitch, roll; METHODS §1). The APC is taken as the IMU point
(no lever arm).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

import numpy as np

from sarmoco.errors import ConfigError
from sarmoco.processing.types import FloatArray
from sarmoco.sim.scenario import Scenario

N_COMPONENTS = 256
"""Sinusoids per turbulence channel."""

BAND_RATIO = 20.0
"""The turbulence spectrum spans f_c / BAND_RATIO .. f_c * BAND_RATIO."""


@dataclass(frozen=True)
class MotionSpec:
    """What deviates from the nominal line, and how much.

    Parameters
    ----------
    kind : {"ideal", "turbulence", "flightlog"}
        See the module docstring.
    cross_track_rms_m, vertical_rms_m : float
        Rms displacement east / down, m (turbulence).
    along_speed_rms_mps : float
        Rms along-track speed variation, m/s (turbulence).
    attitude_rms_rad : float
        Rms of each of roll, pitch, yaw about level flight heading north, rad (turbulence).
    corner_hz : float
        Corner frequency f_c of the spectrum, Hz (turbulence).
    seed : int
        Seed of the random phases and frequencies (turbulence).
    log_path : Path or None
        MAVLink telemetry log (``*.tlog``) for ``flightlog``.
    log_start_s : float
        Offset of the first pulse into the log's usable segment, s (flightlog).
    """

    kind: Literal["ideal", "turbulence", "flightlog"] = "ideal"
    cross_track_rms_m: float = 0.3
    vertical_rms_m: float = 0.3
    along_speed_rms_mps: float = 0.1
    attitude_rms_rad: float = 0.01
    corner_hz: float = 0.5
    seed: int = 0
    log_path: Path | None = None
    log_start_s: float = 0.0


@dataclass(frozen=True)
class Trajectory:
    """True APC kinematics at given times (NED, SI units).

    Parameters
    ----------
    t_s : ndarray, shape (P,)
        Time since the first pulse, s.
    pos_ned, vel_ned, acc_ned : ndarray, shape (P, 3)
        Position (m), velocity (m/s), acceleration (m/s^2).
    quat : ndarray, shape (P, 4)
        Attitude, scalar-first, body to NED.
    """

    t_s: FloatArray
    pos_ned: FloatArray
    vel_ned: FloatArray
    acc_ned: FloatArray
    quat: FloatArray


class Deviation(Protocol):
    """Smooth deviation from the nominal line."""

    def __call__(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Position, velocity, acceleration deviations (P, 3) and Euler angles (P, 3) [roll,
        pitch, yaw], rad."""
        ...


def euler_to_quat(euler_rad: FloatArray) -> FloatArray:
    """Scalar-first quaternions (P, 4) from [roll, pitch, yaw] (P, 3), 3-2-1, body to NED."""
    half = 0.5 * np.asarray(euler_rad, dtype=np.float64)
    cr, cp, cy = np.cos(half).T
    sr, sp, sy = np.sin(half).T
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=1,
    )


def lowpass2_psd(f_hz: FloatArray, corner_hz: float) -> FloatArray:
    """Unnormalised second-order low-pass PSD shape ``1 / (1 + (f/f_c)**2)**2``."""
    return np.asarray(1.0 / (1.0 + (np.asarray(f_hz) / corner_hz) ** 2) ** 2, dtype=np.float64)


@dataclass(frozen=True)
class SinusoidSum:
    """``x(t) = sum_m a_m cos(2 pi f_m t + phi_m)`` and its derivatives.

    Parameters
    ----------
    freq_hz, amp, phase_rad : ndarray, shape (M,)
    """

    freq_hz: FloatArray
    amp: FloatArray
    phase_rad: FloatArray

    @classmethod
    def coloured(cls, rms: float, corner_hz: float, rng: np.random.Generator) -> SinusoidSum:
        """A realisation of the documented low-pass spectrum with total rms ``rms``."""
        edges = np.geomspace(corner_hz / BAND_RATIO, corner_hz * BAND_RATIO, N_COMPONENTS + 1)
        freq = edges[:-1] + rng.random(N_COMPONENTS) * np.diff(edges)
        power = lowpass2_psd(freq, corner_hz) * np.diff(edges)
        amp = np.sqrt(2.0 * power / power.sum()) * rms
        return cls(freq, amp, rng.uniform(0.0, 2.0 * np.pi, N_COMPONENTS))

    def derivatives(self, t_s: FloatArray, order: int = 2) -> list[FloatArray]:
        """[x, x', ..., x^(order)] at ``t_s``, each shape (P,)."""
        w = 2.0 * np.pi * self.freq_hz
        arg = np.outer(np.asarray(t_s, dtype=np.float64), w) + self.phase_rad
        c, s = np.cos(arg), np.sin(arg)
        basis = (c, -s, -c, s)
        return [basis[k % 4] @ (self.amp * w**k) for k in range(order + 1)]


@dataclass(frozen=True)
class TurbulenceDeviation:
    """Seeded turbulence (see the module docstring)."""

    spec: MotionSpec

    def _channels(self) -> list[SinusoidSum]:
        rng = np.random.default_rng(self.spec.seed)
        s = self.spec
        rms = (s.along_speed_rms_mps, s.cross_track_rms_m, s.vertical_rms_m) + (
            s.attitude_rms_rad,
        ) * 3
        return [SinusoidSum.coloured(r, s.corner_hz, rng) for r in rms]

    def __call__(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        along, east, down, *att = self._channels()
        t = np.asarray(t_s, dtype=np.float64)
        pos, vel, acc = (np.zeros((t.size, 3)) for _ in range(3))
        # along track: the process is the speed; position is its integral (a sine sum too)
        v, a = along.derivatives(t, 1)
        integ = SinusoidSum(
            along.freq_hz, along.amp / (2 * np.pi * along.freq_hz), along.phase_rad - np.pi / 2
        )
        pos[:, 0], vel[:, 0], acc[:, 0] = integ.derivatives(t, 0)[0], v, a
        for axis, ch in ((1, east), (2, down)):
            pos[:, axis], vel[:, axis], acc[:, axis] = ch.derivatives(t, 2)
        euler = np.stack([ch.derivatives(t, 0)[0] for ch in att], axis=1)
        return pos, vel, acc, euler


def _deviation(scn: Scenario, spec: MotionSpec) -> Deviation | None:
    if spec.kind == "ideal":
        return None
    if spec.kind == "turbulence":
        if spec.corner_hz <= 0:
            raise ConfigError(f"motion.corner_hz: {spec.corner_hz!r} is not > 0")
        return TurbulenceDeviation(spec)
    if spec.kind == "flightlog":
        raise ConfigError("motion.kind: 'flightlog' is not implemented yet")
    raise ConfigError(f"motion.kind: {spec.kind!r} is not 'ideal', 'turbulence' or 'flightlog'")


def true_trajectory(scn: Scenario, t_s: FloatArray, spec: MotionSpec) -> Trajectory:
    """True APC kinematics at ``t_s`` (seconds since the first pulse).

    The same ``spec`` gives the same continuous trajectory for any choice of ``t_s``.

    Returns
    -------
    Trajectory
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    pos, vel = scn.ideal_track(t)
    acc = np.zeros_like(pos)
    euler = np.zeros_like(pos)
    dev = _deviation(scn, spec)
    if dev is not None:
        dp, dv, da, euler = dev(t)
        pos, vel, acc = pos + dp, vel + dv, da
    return Trajectory(t_s=t, pos_ned=pos, vel_ned=vel, acc_ned=acc, quat=euler_to_quat(euler))
