"""True trajectory: the scenario's straight nominal line plus smooth deviations.

:func:`true_trajectory` gives the kinematics of the INS point (what the INS measures);
:func:`apc_trajectory` moves it by the scenario's lever arm, rotated by the attitude, to the
antenna phase centre (APC: where the echoes come from). Deviations are generated about a
track heading north and then rotated by the scenario's heading (yaw gains the heading and
the crab).

Three kinds (:class:`MotionSpec`):

``ideal``
    The nominal line, level, at the scenario's heading.
``turbulence``
    Cross-track (east) and vertical (down) displacement, along-track speed variation and
    roll/pitch/yaw each follow an independent seeded Gaussian-like process with the
    one-sided power spectral density of a second-order low-pass (Dryden-like;
    :mod:`sarmoco.sim.turbulence`)

        S(f) = S0 / (1 + (f / f_c)**2)**2,   f_c / 10 <= f <= 10 f_c,

    scaled so that its rms is the spec's value (displacement: ``cross_track_rms_m``,
    ``vertical_rms_m``; along-track *speed*: ``along_speed_rms_mps``; each attitude angle:
    ``attitude_rms_rad``). Each process is a sum of ``N_COMPONENTS`` sinusoids at log-spaced,
    randomly jittered frequencies with random phases and amplitudes ``sqrt(2 S(f_m) df_m)``,
    so position, velocity and acceleration are exact analytic derivatives of one smooth
    function, defined for any time (and identical for any sampling of it). With the defaults
    (0.3 m rms, f_c = 0.2 Hz) the cross-track and vertical velocity rms is 0.38 m/s and the
    acceleration rms 1.6 m/s^2 (a small UAV in moderate turbulence).
``flightlog``
    Real UAV motion from an ArduPilot MAVLink telemetry log (``*.tlog``): the velocities of
    LOCAL_POSITION_NED during the airborne part of the first boot (ground speed above
    ``AIRBORNE_SPEED_MPS``) are "straightened": resolved along and across the course smoothed
    with a Gaussian of ``COURSE_SMOOTHING_S`` (so loiter turns become a straight line and only
    the wander about the smoothed path remains), with their mean over the window removed. Each
    channel is fitted by a cubic smoothing spline (GCV) whose integral and derivative give
    position and acceleration, so the three are exact derivatives of one process; position
    deviation is zero at the first pulse. Roll and pitch are the logged ATTITUDE; yaw is the
    logged yaw minus the smoothed course (crab and heading wander).
``survey``
    Straight legs joined by banked 180° turns with the turn rate and the turbulence of the
    real logs (:mod:`sarmoco.sim.survey`; ``legs``, ``leg_s``); the turbulence fields
    above apply, rotated with the heading.

Frames: NED, m, s; ``t_s`` is time since the first pulse. Quaternions are scalar-first and
rotate body to NED (3-2-1 yaw, pitch, roll; docs/methods.md §1).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from scipy.interpolate import BSpline, make_smoothing_spline
from scipy.ndimage import gaussian_filter1d

from sarmoco.errors import ConfigError, DataFileError, NavigationError
from sarmoco.processing.geometry import lever_arm_ned
from sarmoco.processing.types import FloatArray
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.scenario import Scenario
from sarmoco.sim.survey import SurveyDeviation
from sarmoco.sim.turbulence import TurbulenceDeviation


@dataclass(frozen=True)
class Trajectory:
    """True kinematics of one point of the platform at given times (NED, SI units).

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


AIRBORNE_SPEED_MPS = 8.0
"""Log samples with a ground speed above this belong to the airborne segment, m/s."""

COURSE_SMOOTHING_S = 2.0
"""Standard deviation of the Gaussian that smooths the logged course, s."""

LOG_MARGIN_S = 2.0
"""The flight-log trajectory extends this far beyond the window on each side, s."""


@dataclass(frozen=True)
class FlightLog:
    """Airborne segment of a MAVLink log on the autopilot's boot clock.

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        LOCAL_POSITION_NED time since boot, s, strictly increasing.
    vel_ned : ndarray, shape (N, 3)
        Logged velocity, NED, m/s.
    euler_rad : ndarray, shape (N, 3)
        ATTITUDE roll, pitch, unwrapped yaw interpolated to ``t_s``, rad.
    """

    t_s: FloatArray
    vel_ned: FloatArray
    euler_rad: FloatArray


@functools.lru_cache(maxsize=4)
def read_flight_log(path: str) -> FlightLog:
    """Read the longest airborne run of the first boot from a MAVLink ``.tlog``.

    Raises
    ------
    DataFileError
        The file lacks LOCAL_POSITION_NED / ATTITUDE or has no airborne segment.
    """
    from pymavlink import mavutil

    try:
        conn = mavutil.mavlink_connection(path)
    except OSError as exc:
        raise DataFileError(f"flight log {path}: {exc}") from exc
    pos_rows: list[tuple[float, float, float, float]] = []
    att_rows: list[tuple[float, float, float, float]] = []
    while (msg := conn.recv_match(type=["LOCAL_POSITION_NED", "ATTITUDE"])) is not None:
        t = msg.time_boot_ms * 1e-3
        if msg.get_type() == "LOCAL_POSITION_NED":
            pos_rows.append((t, msg.vx, msg.vy, msg.vz))
        else:
            att_rows.append((t, msg.roll, msg.pitch, msg.yaw))
    if len(pos_rows) < 10 or len(att_rows) < 10:
        raise DataFileError(f"flight log {path}: too few LOCAL_POSITION_NED / ATTITUDE messages")
    pos = _longest_increasing(np.array(pos_rows))
    att = _longest_increasing(np.array(att_rows))
    airborne = np.hypot(pos[:, 1], pos[:, 2]) > AIRBORNE_SPEED_MPS
    edges = np.flatnonzero(np.diff(np.concatenate(([0], airborne.astype(int), [0]))))
    starts, stops = edges[::2], edges[1::2]
    if starts.size == 0:
        raise DataFileError(f"flight log {path}: no samples above {AIRBORNE_SPEED_MPS} m/s")
    k = int(np.argmax(pos[stops - 1, 0] - pos[starts, 0]))
    seg = pos[starts[k] : stops[k]]
    euler = np.stack(
        [np.interp(seg[:, 0], att[:, 0], a) for a in (att[:, 1], att[:, 2], np.unwrap(att[:, 3]))],
        1,
    )
    return FlightLog(t_s=seg[:, 0], vel_ned=seg[:, 1:4], euler_rad=euler)


def _longest_increasing(rows: FloatArray) -> FloatArray:
    """Rows of the longest run with strictly increasing first column (one boot)."""
    breaks = np.flatnonzero(np.diff(rows[:, 0]) <= 0) + 1
    bounds = np.concatenate(([0], breaks, [rows.shape[0]]))
    k = int(np.argmax(np.diff(bounds)))
    return rows[bounds[k] : bounds[k + 1]]


@dataclass(frozen=True)
class FlightLogDeviation:
    """Straightened deviations of a logged flight (see the module docstring).

    Parameters
    ----------
    t_first_pulse_log_s : float
        Log boot time of the first pulse, s.
    t_lo_s, t_hi_s : float
        Interval of simulation time the deviation is defined on, s.
    vel : list of BSpline
        Along (north), cross (east), down velocity deviation vs log time, m/s.
    vel_mean : ndarray, shape (3,)
        Mean of each spline over the fitted interval (removed), m/s.
    att : list of BSpline
        Roll, pitch, yaw deviation vs log time, rad.
    """

    t_first_pulse_log_s: float
    t_lo_s: float
    t_hi_s: float
    vel: list[BSpline]
    vel_mean: FloatArray
    att: list[BSpline]

    @classmethod
    def from_spec(cls, spec: MotionSpec) -> FlightLogDeviation:
        """Fit the deviations of the window ``spec`` selects in ``spec.log_path``."""
        if spec.log_path is None:
            raise ConfigError("motion.log_path: required for kind 'flightlog'")
        log = read_flight_log(str(spec.log_path))
        a = float(log.t_s[0]) + spec.log_start_s
        lo, hi = a - LOG_MARGIN_S, a + spec.log_window_s + LOG_MARGIN_S
        if lo < log.t_s[0] or hi > log.t_s[-1]:
            raise ConfigError(
                f"motion.log_start_s/log_window_s: {spec.log_start_s}/{spec.log_window_s} s need "
                f"log time {lo:.1f}..{hi:.1f} s, the airborne segment is "
                f"{log.t_s[0]:.1f}..{log.t_s[-1]:.1f} s (margins {LOG_MARGIN_S} s)"
            )
        dt = float(np.median(np.diff(log.t_s)))
        course = np.unwrap(np.arctan2(log.vel_ned[:, 1], log.vel_ned[:, 0]))
        course = gaussian_filter1d(course, COURSE_SMOOTHING_S / dt, mode="nearest")
        c, s = np.cos(course), np.sin(course)
        v = log.vel_ned
        straight = np.stack([v[:, 0] * c + v[:, 1] * s, -v[:, 0] * s + v[:, 1] * c, v[:, 2]], 1)
        yaw = np.unwrap(np.angle(np.exp(1j * (log.euler_rad[:, 2] - course))))
        att = np.stack([log.euler_rad[:, 0], log.euler_rad[:, 1], yaw], 1)
        sel = (log.t_s >= lo - 2 * dt) & (log.t_s <= hi + 2 * dt)
        t = log.t_s[sel]
        vel = [make_smoothing_spline(t, straight[sel, i]) for i in range(3)]
        mean = np.array(
            [(sp.antiderivative()(hi) - sp.antiderivative()(lo)) / (hi - lo) for sp in vel]
        )
        return cls(
            a, lo - a, hi - a, vel, mean, [make_smoothing_spline(t, att[sel, i]) for i in range(3)]
        )

    def __call__(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        t = np.asarray(t_s, dtype=np.float64)
        if t.size and (t.min() < self.t_lo_s or t.max() > self.t_hi_s):
            raise NavigationError(
                f"flightlog trajectory covers {self.t_lo_s:.2f}..{self.t_hi_s:.2f} s, asked for "
                f"{t.min():.2f}..{t.max():.2f} s (raise log_window_s)"
            )
        tl = t + self.t_first_pulse_log_s
        t0 = self.t_first_pulse_log_s
        pos = np.stack(
            [
                sp.antiderivative()(tl) - sp.antiderivative()(t0) - m * t
                for sp, m in zip(self.vel, self.vel_mean, strict=True)
            ],
            1,
        )
        vel = np.stack([sp(tl) - m for sp, m in zip(self.vel, self.vel_mean, strict=True)], 1)
        acc = np.stack([sp.derivative()(tl) for sp in self.vel], 1)
        euler = np.stack([sp(tl) for sp in self.att], 1)
        return pos, vel, acc, euler


def _deviation(scn: Scenario, spec: MotionSpec) -> Deviation | None:
    if spec.kind == "ideal":
        return None
    if spec.kind == "turbulence":
        if spec.corner_hz <= 0:
            raise ConfigError(f"motion.corner_hz: {spec.corner_hz!r} is not > 0")
        return TurbulenceDeviation(spec)
    if spec.kind == "flightlog":
        return FlightLogDeviation.from_spec(spec)
    if spec.kind == "survey":
        return SurveyDeviation(scn, spec)
    raise ConfigError(
        f"motion.kind: {spec.kind!r} is not 'ideal', 'turbulence', 'flightlog' or 'survey'"
    )


def true_trajectory(scn: Scenario, t_s: npt.ArrayLike, spec: MotionSpec) -> Trajectory:
    """True kinematics of the INS point at ``t_s`` (seconds since the first pulse).

    The scenario's nominal line is the antenna phase centre's at the steady attitude (level,
    yawed by the heading and the crab: :attr:`Scenario.body_to_ned`): the INS point flies it
    offset by minus the lever arm turned by that attitude, so that the APC
    (:func:`apc_trajectory`) is on the nominal line whenever the attitude is steady, and the
    scenario's altitude and slant ranges stay those of the antenna. The attitude's yaw is the
    heading plus the crab plus the deviation's yaw; the velocity stays along the track.

    The same ``spec`` gives the same continuous trajectory for any choice of ``t_s``.

    Returns
    -------
    Trajectory
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    pos, vel = scn.ideal_track(t)
    pos = pos - scn.body_to_ned @ np.asarray(scn.lever_arm_m, dtype=np.float64)
    acc = np.zeros_like(pos)
    euler = np.zeros_like(pos)
    dev = _deviation(scn, spec)
    if dev is not None:
        dp, dv, da, euler = dev(t)
        rot = scn.heading_to_ned
        pos, vel, acc = pos + dp @ rot.T, vel + dv @ rot.T, da @ rot.T
    euler = euler + np.array([0.0, 0.0, scn.heading_rad + scn.crab_rad])
    return Trajectory(t_s=t, pos_ned=pos, vel_ned=vel, acc_ned=acc, quat=euler_to_quat(euler))


ARM_RATE_STEP_S = 1e-4
"""Half step of the central differences that give the lever arm's rate and acceleration, s."""


def apc_trajectory(scn: Scenario, t_s: npt.ArrayLike, spec: MotionSpec) -> Trajectory:
    """True kinematics of the antenna phase centre: the INS point plus ``R(q) l``.

    ``l`` is ``scn.lever_arm_m`` (body frame); the arm's velocity and acceleration are
    central differences of the continuous attitude (step :data:`ARM_RATE_STEP_S`).

    Returns
    -------
    Trajectory
        Position, velocity and acceleration of the APC; attitude of the platform.
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    imu = true_trajectory(scn, t, spec)
    arm_body = np.asarray(scn.lever_arm_m, dtype=np.float64)
    if not arm_body.any():
        return imu
    h = ARM_RATE_STEP_S
    arms = [
        lever_arm_ned(q, arm_body)
        for q in (
            true_trajectory(scn, t - h, spec).quat,
            imu.quat,
            true_trajectory(scn, t + h, spec).quat,
        )
    ]
    return Trajectory(
        t_s=t,
        pos_ned=imu.pos_ned + arms[1],
        vel_ned=imu.vel_ned + (arms[2] - arms[0]) / (2.0 * h),
        acc_ned=imu.acc_ned + (arms[2] - 2.0 * arms[1] + arms[0]) / h**2,
        quat=imu.quat,
    )
