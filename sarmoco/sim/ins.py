"""INS / GNSS measurement model: datasheet-driven errors on the device's own clock.

A GNSS-aided INS outputs Kalman-filtered velocity and attitude. Its error is not white noise per
sample: between GNSS updates the mechanisation integrates the accelerometer (gyro) white noise
and residual bias, and the filter pulls the integral back towards the aiding. This module models
each error channel (velocity per NED axis, attitude per body axis, independent, 1-sigma) as the
state of that loop, a first-order low-pass of time constant ``tau`` driven by the sensor::

    dx/dt = -x / tau + n(t) + b(t)

- ``n``: the sensor's white noise, density ``N`` (velocity random walk VRW for velocity, angle
  random walk ARW for attitude): over lags much shorter than ``tau`` the error is a random walk,
  ``E[(x(t+d) - x(t))^2] = N^2 d``;
- ``b``: the residual sensor bias, a first-order Gauss-Markov process with the datasheet's
  in-run bias instability as rms and a correlation time of :data:`BIAS_CORRELATION_S`;
- ``tau``: the aiding loop's time constant, the one value for which the stationary rms of ``x``,
  ``N^2 tau / 2 + sigma_b^2 tau^2 T_b / (T_b + tau)``, equals the datasheet's aided accuracy
  (:func:`aided_time_constant_s`). This is a stated model of the filter, not a simulation of a
  particular vendor's Kalman filter: GNSS noise injected through the filter gain is folded into
  the datasheet rms, not modelled as a separate term.

Grades (the keys of :data:`GRADES`, accepted by ``--ins-grade``) and the named units they model:

===========  ================================  ======= ======= ========= ======= ====== ===== =====
grade        unit                              VRW     acc BI  ARW       gyro BI v rms  r/p   hdg
                                               m/s/√h  mg      °/√h      °/h     m/s    °     °
===========  ================================  ======= ======= ========= ======= ====== ===== =====
ideal        exact navigation                  0       0       0         0       0      0     0
tactical     NovAtel SPAN-IGM-S1 (STIM300 IMU) 0.03    0.1     0.15      0.5     0.02   0.01  0.04
ellipse-d    SBG Ellipse2-D                    0.033   0.014   0.15      7       0.03   0.05  0.2
mems         Xsens MTi-G-710                   0.0353  0.015   0.6       10      0.1    0.2   1.0
gps          standalone GNSS receiver          (white per fix, see below; no IMU)
===========  ================================  ======= ======= ========= ======= ====== ===== =====

Sources of the figures (1-sigma, as printed):

- ``tactical``, SPAN-IGM (STIM300): accelerometer bias stability 0.1 mg, random walk
  0.03 m/s/√h, gyro bias stability 0.5 °/h, random walk 0.15 °/√h (EURASIP J. Adv. Signal
  Process. 2023, doi 10.1186/s13634-023-01044-9, Table 4). Aided accuracies 0.02 m/s, roll/pitch
  0.01°, heading 0.04° are NovAtel's SPAN-IGM-S1 RTK figures as recalled, not found in the
  stored pages. Output 100 Hz (the SPAN family's INS solution rate, SPAN-CPT manual Table 8).
- ``ellipse-d``, SBG Ellipse2: VRW 0.033 m/s/√h, accelerometer bias stability 0.014 mg, ARW
  0.15 °/√h, gyro bias stability 7 °/h (NAVIGATION, ION, sensor table "Ellipse2 industrial
  grade"; its 1 h bias time constant is :data:`BIAS_CORRELATION_S`). Aided accuracies 0.03 m/s,
  roll/pitch 0.05°, heading 0.2° (dual antenna) and 200 Hz output are SBG's Ellipse2-D leaflet
  figures as recalled, not found in the stored pages.
- ``mems``, Xsens MTi-G-710: velocity 0.1 m/s 1σ RMS at 400 Hz GPS/INS output (MTi User Manual
  MT0605P §4.4); its 100-series IMU as in the MTi-300 datasheet (Movella 2023): gyro in-run bias
  stability 10 °/h, noise density 0.01 °/s/√Hz (= 0.6 °/√h), accelerometer in-run bias stability
  15 µg, noise density 60 µg/√Hz (= 0.0353 m/s/√h), roll/pitch 0.2° RMS, heading 1° RMS.
- ``gps``: velocity white 50 mm/s per fix plus a 20 mm/s turn-on bias walking 2 mm/s/√s;
  position 1.15 m/axis offset (≈ 2 m 3-D), 0.3 m white, 0.05 m/√s walk; 10 Hz whatever the rate
  asked; attitude level with heading = course.

The loop time constants these figures give (velocity / roll-pitch / heading): tactical ≈ 20 /
27 / 223 s, ellipse-d ≈ 221 / 25 / 104 s, mems ≈ 742 / 70 / 375 s; almost all of the velocity
rms is the residual accelerometer bias through the loop (tactical: 20 mm/s of it, 1.6 mm/s
from the VRW). Within a synthetic aperture
of a second the velocity error is then an offset, a slow ramp and the VRW random walk, not
independent noise per sample.

Clock: the device counts ``t_dev = epoch + offset + (t_gps - epoch) (1 + drift_ppm 1e-6)`` and
samples at a uniform rate on that clock; the GPS stamps returned beside the device stamps are
the truth mapping of each device tick (what a perfect clock sync would recover).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.signal import lfilter

from sarmoco.errors import ConfigError
from sarmoco.processing.types import FloatArray, IntArray, NavSamples
from sarmoco.sim.trajectory import Trajectory, euler_to_quat

G0_MPS2 = 9.80665
"""Standard gravity, m/s^2 (datasheets' g and mg)."""

BIAS_CORRELATION_S = 3600.0
"""Correlation time of the residual sensor bias, s: datasheets give the in-run bias instability
but no time constant; 1 h is the value the NAVIGATION (ION) study cited above assumes."""


@dataclass(frozen=True)
class InsGrade:
    """One navigation source, in its datasheet's units (see the module table), 1-sigma.

    Parameters
    ----------
    name : str
        Grade key.
    unit : str
        The real unit it models.
    output_rate_hz : float
        Datasheet output rate, Hz (the default of :func:`measure_ins`).
    vel_rms_mps : float
        Aided velocity accuracy per NED axis, m/s.
    vrw_mps_per_sqrt_h : float
        Accelerometer velocity random walk, m/s/√h.
    accel_bias_mg : float
        Accelerometer in-run bias instability, mg.
    roll_pitch_rms_deg, heading_rms_deg : float
        Aided attitude accuracy about the body x, y axes and the z axis, degrees.
    arw_deg_per_sqrt_h : float
        Gyro angle random walk, °/√h.
    gyro_bias_deg_per_h : float
        Gyro in-run bias instability, °/h.
    vel_noise_mps, vel_bias_mps, vel_bias_drift_mps_per_sqrt_s : float
        Unaided (GNSS receiver) velocity: white per fix, turn-on bias (m/s), bias random walk
        (m/s/√s).
    has_position : bool
        Whether the source outputs position (``pos_*``: white per fix, turn-on offset per axis,
        random walk, m and m/√s).
    attitude_from_course : bool
        No attitude: level, heading = course over ground.
    rate_fixed : bool
        Output at ``output_rate_hz`` whatever rate is asked.
    """

    name: str
    unit: str = ""
    output_rate_hz: float = 200.0
    vel_rms_mps: float = 0.0
    vrw_mps_per_sqrt_h: float = 0.0
    accel_bias_mg: float = 0.0
    roll_pitch_rms_deg: float = 0.0
    heading_rms_deg: float = 0.0
    arw_deg_per_sqrt_h: float = 0.0
    gyro_bias_deg_per_h: float = 0.0
    vel_noise_mps: float = 0.0
    vel_bias_mps: float = 0.0
    vel_bias_drift_mps_per_sqrt_s: float = 0.0
    has_position: bool = False
    pos_noise_m: float = 0.0
    pos_bias_m: float = 0.0
    pos_drift_m_per_sqrt_s: float = 0.0
    attitude_from_course: bool = False
    rate_fixed: bool = False

    def velocity_channel(self) -> AidedChannel:
        """The aided velocity error of one NED axis, SI units."""
        return AidedChannel(
            self.vel_rms_mps,
            self.vrw_mps_per_sqrt_h / 60.0,
            self.accel_bias_mg * 1e-3 * G0_MPS2,
        )

    def attitude_channels(self) -> tuple[AidedChannel, AidedChannel, AidedChannel]:
        """The aided attitude error about body x, y, z, SI units (rad)."""
        arw = math.radians(self.arw_deg_per_sqrt_h) / 60.0
        bias = math.radians(self.gyro_bias_deg_per_h) / 3600.0
        rp = AidedChannel(math.radians(self.roll_pitch_rms_deg), arw, bias)
        return rp, rp, AidedChannel(math.radians(self.heading_rms_deg), arw, bias)

    @property
    def vel_std_mps(self) -> float:
        """Total velocity 1-sigma per axis, m/s (what the unit reports as its accuracy)."""
        return math.hypot(self.vel_rms_mps, self.vel_noise_mps, self.vel_bias_mps)

    @property
    def att_std_rad(self) -> float:
        """Roll/pitch 1-sigma, rad (what the unit reports as its attitude accuracy)."""
        return math.radians(self.roll_pitch_rms_deg)


@dataclass(frozen=True)
class AidedChannel:
    """One error channel of an aided INS (see the module docstring), SI units.

    Parameters
    ----------
    rms : float
        Datasheet aided accuracy (m/s or rad).
    noise_density : float
        Sensor white noise density (m/s/√s or rad/√s).
    bias_sigma : float
        Residual bias rms (m/s² or rad/s), correlation :data:`BIAS_CORRELATION_S`.
    """

    rms: float
    noise_density: float
    bias_sigma: float

    @property
    def tau_s(self) -> float:
        """Loop time constant, s (:func:`aided_time_constant_s`)."""
        return aided_time_constant_s(self.rms, self.noise_density, self.bias_sigma)

    @property
    def noise_rms(self) -> float:
        """Stationary rms of the noise-driven part, ``N sqrt(tau / 2)``."""
        return self.noise_density * math.sqrt(0.5 * self.tau_s) if self.rms > 0 else 0.0

    @property
    def bias_rms(self) -> float:
        """Stationary rms of the bias-driven part, ``sigma_b tau sqrt(T_b / (T_b + tau))``."""
        if self.rms == 0:
            return 0.0
        tau = self.tau_s
        return self.bias_sigma * tau * math.sqrt(BIAS_CORRELATION_S / (BIAS_CORRELATION_S + tau))


def aided_time_constant_s(rms: float, noise_density: float, bias_sigma: float) -> float:
    """Time constant of the aiding loop that bounds a sensor error at the datasheet accuracy.

    Solves ``N^2 tau / 2 + sigma_b^2 tau^2 T_b / (T_b + tau) = rms^2`` (monotonic in ``tau``).

    Parameters
    ----------
    rms : float
        Aided accuracy, 1-sigma (m/s or rad); > 0.
    noise_density : float
        White noise density N (m/s/√s or rad/√s).
    bias_sigma : float
        Residual bias rms sigma_b (m/s² or rad/s).

    Returns
    -------
    float
        tau, s.
    """
    if not rms > 0 or (noise_density <= 0 and bias_sigma <= 0):
        raise ConfigError(
            f"ins: an aided accuracy {rms!r} needs a positive accuracy and a sensor noise density"
            f" ({noise_density!r}) or bias instability ({bias_sigma!r}) that produce it"
        )
    tb = BIAS_CORRELATION_S

    def excess(tau: float) -> float:
        return (
            noise_density**2 * tau / 2 + bias_sigma**2 * tau**2 * tb / (tb + tau) - rms**2
        ) / rms**2

    hi = 1.0
    while excess(hi) < 0:
        hi *= 10.0
    return float(brentq(excess, 0.0, hi, xtol=1e-9 * hi, rtol=1e-12))


GRADES: dict[str, InsGrade] = {
    "ideal": InsGrade("ideal", "exact navigation", has_position=True),
    "tactical": InsGrade(
        "tactical",
        "NovAtel SPAN-IGM-S1 (Sensonor STIM300 IMU)",
        output_rate_hz=100.0,
        vel_rms_mps=0.02,
        vrw_mps_per_sqrt_h=0.03,
        accel_bias_mg=0.1,
        roll_pitch_rms_deg=0.01,
        heading_rms_deg=0.04,
        arw_deg_per_sqrt_h=0.15,
        gyro_bias_deg_per_h=0.5,
    ),
    "ellipse-d": InsGrade(
        "ellipse-d",
        "SBG Ellipse2-D",
        output_rate_hz=200.0,
        vel_rms_mps=0.03,
        vrw_mps_per_sqrt_h=0.033,
        accel_bias_mg=0.014,
        roll_pitch_rms_deg=0.05,
        heading_rms_deg=0.2,
        arw_deg_per_sqrt_h=0.15,
        gyro_bias_deg_per_h=7.0,
    ),
    "mems": InsGrade(
        "mems",
        "Xsens MTi-G-710",
        output_rate_hz=400.0,
        vel_rms_mps=0.1,
        vrw_mps_per_sqrt_h=60e-6 * G0_MPS2 * 60.0,  # 60 µg/√Hz
        accel_bias_mg=0.015,
        roll_pitch_rms_deg=0.2,
        heading_rms_deg=1.0,
        arw_deg_per_sqrt_h=0.01 * 60.0,  # 0.01 °/s/√Hz
        gyro_bias_deg_per_h=10.0,
    ),
    "gps": InsGrade(
        "gps",
        "standalone GNSS receiver",
        output_rate_hz=10.0,
        vel_noise_mps=0.05,
        vel_bias_mps=0.02,
        vel_bias_drift_mps_per_sqrt_s=0.002,
        has_position=True,
        pos_noise_m=0.3,
        pos_bias_m=2.0 / math.sqrt(3.0),
        pos_drift_m_per_sqrt_s=0.05,
        attitude_from_course=True,
        rate_fixed=True,
    ),
}
"""The documented grades by name (module table)."""


@dataclass(frozen=True)
class InsMeasurement:
    """Simulated navigation samples and their error realisation.

    Parameters
    ----------
    nav : NavSamples
        Measurements stamped with the true GPS time of each device tick, ns.
    t_device_ns : ndarray of int64, shape (N,)
        The same samples' stamps on the device clock, ns.
    grade : InsGrade
        Error levels used.
    vel_error_ned : ndarray, shape (N, 3)
        Measured minus true velocity, m/s.
    vel_bias_ned : ndarray, shape (N, 3)
        Its bias-driven part, m/s: the residual accelerometer bias through the aiding loop, plus
        the turn-on bias and walk of an unaided receiver.
    att_error_rad : ndarray, shape (N, 3)
        Body-frame rotation vector of the attitude error, rad (zero for course attitude).
    pos_error_ned : ndarray, shape (N, 3) or None
        Measured minus true position, m.
    """

    nav: NavSamples
    t_device_ns: IntArray
    grade: InsGrade
    vel_error_ned: FloatArray
    vel_bias_ned: FloatArray
    att_error_rad: FloatArray
    pos_error_ned: FloatArray | None


def quat_multiply(q: FloatArray, r: FloatArray) -> FloatArray:
    """Hamilton product of scalar-first quaternions, row-wise (N, 4)."""
    w1, x1, y1, z1 = q.T
    w2, x2, y2, z2 = r.T
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=1,
    )


def rotvec_to_quat(e: FloatArray) -> FloatArray:
    """Scalar-first quaternions (N, 4) of rotation vectors (N, 3), rad."""
    angle = np.linalg.norm(e, axis=1)
    half = 0.5 * angle
    scale = np.where(angle > 0, np.sin(half) / np.where(angle > 0, angle, 1.0), 0.5)
    return np.concatenate([np.cos(half)[:, None], e * scale[:, None]], axis=1)


def _bias_process(
    rng: np.random.Generator, t_s: FloatArray, turn_on: float, walk: float
) -> FloatArray:
    """Turn-on bias plus random walk, (N, 3)."""
    b0 = rng.standard_normal(3) * turn_on
    dt = np.diff(t_s, prepend=t_s[0])
    steps = rng.standard_normal((t_s.size, 3)) * (walk * np.sqrt(dt))[:, None]
    return b0 + np.cumsum(steps, axis=0)


def _ar1(phi: float, first: float, drive: FloatArray) -> FloatArray:
    """``y[0] = first``, ``y[k] = phi y[k-1] + drive[k-1]``: length ``drive.size + 1``."""
    return np.asarray(lfilter([1.0], [1.0, -phi], np.concatenate([[first], drive])))


def aided_error(
    rng: np.random.Generator, n: int, dt_s: float, channel: AidedChannel
) -> tuple[FloatArray, FloatArray]:
    """One stationary realisation of an aided error channel at uniform steps ``dt_s``.

    Returns
    -------
    total, bias_part : ndarray, shape (n,)
        The error and its bias-driven part (units of ``channel.rms``).
    """
    draws = rng.standard_normal((4, n))
    if channel.rms == 0:
        return np.zeros(n), np.zeros(n)
    tau, tb = channel.tau_s, BIAS_CORRELATION_S
    phi, phi_b = math.exp(-dt_s / tau), math.exp(-dt_s / tb)
    sb = channel.bias_sigma
    bias = _ar1(phi_b, sb * draws[0, 0], sb * math.sqrt(1 - phi_b**2) * draws[0, 1:])
    # the bias-driven part starts from its stationary law given the bias (cov c, variance v)
    c = sb**2 * tau * tb / (tau + tb)
    v = channel.bias_rms**2
    x0 = 0.0
    if sb > 0:
        x0 = (c / sb**2) * bias[0] + math.sqrt(max(v - c**2 / sb**2, 0.0)) * draws[1, 0]
    xb = _ar1(phi, x0, tau * (1 - phi) * bias[:-1])
    q = channel.noise_density * math.sqrt(0.5 * tau * (1 - phi**2))
    xn = _ar1(phi, channel.noise_rms * draws[2, 0], q * draws[3, 1:])
    return xb + xn, xb


def device_ticks(
    t0_s: float,
    t1_s: float,
    rate_hz: float,
    epoch_ns: int,
    clock_offset_s: float,
    clock_drift_ppm: float,
) -> tuple[IntArray, IntArray]:
    """Uniform device-clock ticks covering GPS time [t0_s, t1_s] and their true GPS stamps.

    Returns
    -------
    t_device_ns, t_gps_ns : ndarray of int64
    """
    gain = 1.0 + clock_drift_ppm * 1e-6
    dev0 = clock_offset_s + t0_s * gain
    dev1 = clock_offset_s + t1_s * gain
    n0, n1 = math.ceil(dev0 * rate_hz), math.floor(dev1 * rate_hz)
    ticks = np.arange(n0, n1 + 1, dtype=np.int64)
    t_dev_rel_ns = np.round(ticks * (1e9 / rate_hz)).astype(np.int64)
    t_gps_rel_s = (t_dev_rel_ns * 1e-9 - clock_offset_s) / gain
    return epoch_ns + t_dev_rel_ns, epoch_ns + np.round(t_gps_rel_s * 1e9).astype(np.int64)


def measure_ins(
    traj_fn: Callable[[FloatArray], Trajectory],
    t0_s: float,
    t1_s: float,
    rate_hz: float | None,
    grade: InsGrade | str,
    clock_offset_s: float = 0.0,
    clock_drift_ppm: float = 0.0,
    seed: int = 0,
    epoch_ns: int = 0,
) -> InsMeasurement:
    """Sample a navigation source along a true trajectory.

    Parameters
    ----------
    traj_fn : callable
        ``traj_fn(t_s) -> Trajectory``, true kinematics at GPS times ``epoch + t_s``.
    t0_s, t1_s : float
        GPS time span to cover, s after ``epoch_ns``.
    rate_hz : float or None
        Output rate on the device clock, Hz; None: the unit's datasheet rate (grades with a
        fixed rate ignore it).
    grade : InsGrade or str
        Error levels, or a key of :data:`GRADES`.
    clock_offset_s, clock_drift_ppm : float
        Device clock offset at the epoch (s) and rate error (ppm) against GPS.
    seed : int
        Seed of the error realisation.
    epoch_ns : int
        GPS time of ``t_s = 0``, ns.

    Returns
    -------
    InsMeasurement
    """
    g = GRADES.get(grade) if isinstance(grade, str) else grade
    if g is None:
        raise ConfigError(f"ins.grade: {grade!r} is not one of {', '.join(GRADES)}")
    rate = g.output_rate_hz if g.rate_fixed or rate_hz is None else rate_hz
    if not rate > 0 or not t1_s > t0_s:
        raise ConfigError(f"ins: rate {rate!r} Hz, span [{t0_s}, {t1_s}] s are not valid")
    t_dev, t_gps = device_ticks(t0_s, t1_s, rate, epoch_ns, clock_offset_s, clock_drift_ppm)
    t_s = ((t_gps - epoch_ns) * 1e-9).astype(np.float64)
    n = t_s.size
    dt = float(t_s[-1] - t_s[0]) / (n - 1) if n > 1 else 1.0 / rate
    truth = traj_fn(t_s)
    rng = np.random.default_rng(seed)
    aided = [aided_error(rng, n, dt, g.velocity_channel()) for _ in range(3)]
    receiver = _bias_process(rng, t_s, g.vel_bias_mps, g.vel_bias_drift_mps_per_sqrt_s)
    vel_bias = np.stack([b for _, b in aided], axis=1) + receiver
    vel_err = np.stack([x for x, _ in aided], axis=1) + receiver
    vel_err = vel_err + rng.standard_normal((n, 3)) * g.vel_noise_mps
    vel = truth.vel_ned + vel_err
    if g.attitude_from_course:
        att_err = np.zeros((n, 3))
        course = np.arctan2(vel[:, 1], vel[:, 0])
        quat = euler_to_quat(np.stack([np.zeros_like(course), np.zeros_like(course), course], 1))
    else:
        att_err = np.stack([aided_error(rng, n, dt, c)[0] for c in g.attitude_channels()], 1)
        quat = quat_multiply(truth.quat, rotvec_to_quat(att_err))
    pos_err = None
    pos = None
    if g.has_position:
        pos_err = _bias_process(rng, t_s, g.pos_bias_m, g.pos_drift_m_per_sqrt_s)
        pos_err = pos_err + rng.standard_normal((n, 3)) * g.pos_noise_m
        pos = truth.pos_ned + pos_err
    nav = NavSamples(t_ns=t_gps, vel_ned=vel, quat=quat, pos_ned=pos)
    return InsMeasurement(nav, t_dev, g, vel_err, vel_bias, att_err, pos_err)
