"""INS measurement model: noise, bias and drift statistics, attitude errors, clock mapping."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from sarmoco.errors import ConfigError
from sarmoco.processing.types import FloatArray
from sarmoco.sim.ins import GRADES, InsGrade, device_ticks, measure_ins, quat_multiply
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.trajectory import Trajectory, true_trajectory

SCN = load_preset("ku-vehicle", scale=0.1)
MOTION = MotionSpec(kind="turbulence", seed=2)
EPOCH = SCN.t0_ns


def _truth(t: npt.ArrayLike) -> Trajectory:
    return true_trajectory(SCN, t, MOTION)


def _level(t: FloatArray) -> Trajectory:
    """Cheap truth for the error statistics (the errors do not depend on the motion)."""
    return true_trajectory(SCN, t, MotionSpec())


def test_ideal_is_exact() -> None:
    m = measure_ins(_truth, -0.5, 3.0, 200.0, "ideal", epoch_ns=EPOCH)
    tr = _truth((m.nav.t_ns - EPOCH) * 1e-9)
    np.testing.assert_allclose(m.nav.vel_ned, tr.vel_ned, atol=1e-12)
    np.testing.assert_allclose(m.nav.quat, tr.quat, atol=1e-12)
    assert m.nav.pos_ned is not None
    np.testing.assert_allclose(m.nav.pos_ned, tr.pos_ned, atol=1e-12)
    assert np.all(np.diff(m.nav.t_ns) == 5_000_000) and m.nav.t_ns[0] >= EPOCH - 500_000_000


G0 = 9.80665
T_BIAS_S = 3600.0  # the bias correlation time the module states
CHANNELS = ("v north", "v east", "v down", "roll", "pitch", "yaw")


def _datasheet_channels(g: InsGrade) -> list[tuple[float, float, float]]:
    """(rms, white density, bias sigma) in SI from the grade's datasheet figures: the oracle.

    Velocity (m/s, m/s/sqrt(s), m/s^2) for N, E, D; attitude (rad, rad/sqrt(s), rad/s) about
    body x, y (the roll/pitch figure) and z (the heading figure).
    """
    vel = (g.vel_rms_mps, g.vrw_mps_per_sqrt_h / 60.0, g.accel_bias_mg * 1e-3 * G0)
    arw = math.radians(g.arw_deg_per_sqrt_h) / 60.0
    gyro_bias = math.radians(g.gyro_bias_deg_per_h) / 3600.0
    rp = (math.radians(g.roll_pitch_rms_deg), arw, gyro_bias)
    return [vel, vel, vel, rp, rp, (math.radians(g.heading_rms_deg), arw, gyro_bias)]


def _loop_tau(rms: float, density: float, bias: float) -> float:
    """Bisection for the loop time constant whose stationary variance is rms^2, s."""
    lo, hi = 0.0, 1e7
    for _ in range(200):
        tau = 0.5 * (lo + hi)
        var = density**2 * tau / 2 + bias**2 * tau**2 * T_BIAS_S / (T_BIAS_S + tau)
        lo, hi = (tau, hi) if var < rms**2 else (lo, tau)
    return tau


def _structure_theory(lag_s: float, rms: float, density: float, bias: float) -> float:
    """E[(x(t+lag) - x(t))^2] of white noise plus a Gauss-Markov bias through 1/(s + 1/tau)."""
    tau, tb = _loop_tau(rms, density, bias), T_BIAS_S

    def cov(lag: float) -> float:
        noise = 0.5 * density**2 * tau * math.exp(-lag / tau)
        drift = tb * math.exp(-lag / tb) - tau * math.exp(-lag / tau)
        return noise + bias**2 * tau**2 * tb * drift / (tb**2 - tau**2)

    return 2.0 * (cov(0.0) - cov(lag_s))


@pytest.mark.parametrize("grade", ["tactical", "ellipse-d", "mems"])
def test_aided_errors_match_the_datasheet(grade: str) -> None:
    """rms = datasheet accuracy; VRW/ARW random walk at short lags; decorrelation over tau.

    The oracle is computed here from the grade's datasheet figures (own unit conversions, own
    loop time constant); the statistics pool 60 realisations of 8 slowest time constants.
    Lags: one sample (the random-walk slope N^2), tau / 4, tau and 3 tau of each channel.
    """
    g = GRADES[grade]
    chans = _datasheet_channels(g)
    dur = 8.0 * max(_loop_tau(*c) for c in chans)
    runs = [
        measure_ins(_level, 0.0, dur, 1500 / dur, grade, seed=s, epoch_ns=EPOCH) for s in range(60)
    ]
    step_s = float(np.mean(np.diff(runs[0].nav.t_ns))) * 1e-9
    err = np.concatenate(
        [np.stack([m.vel_error_ned for m in runs]), np.stack([m.att_error_rad for m in runs])], 2
    )
    for j, (rms, density, bias) in enumerate(chans):
        x = err[:, :, j]
        assert np.sqrt(np.mean(x**2)) == pytest.approx(rms, rel=0.2), CHANNELS[j]
        tau = _loop_tau(rms, density, bias)
        for lag_s, tol in ((step_s, 0.05), (tau / 4, 0.15), (tau, 0.2), (3 * tau, 0.3)):
            k = max(1, round(lag_s / step_s))
            got = float(np.mean(np.square(x[:, k:] - x[:, :-k])))
            want = _structure_theory(k * step_s, rms, density, bias)
            print(f"{grade} {CHANNELS[j]} lag {k * step_s:8.2f} s: {got / want:.3f}")
            assert got == pytest.approx(want, rel=tol), (CHANNELS[j], k * step_s)
        if j == 0:  # the residual accelerometer bias through the loop, rms
            part = np.stack([m.vel_bias_ned for m in runs])
            want_rms = bias * tau * math.sqrt(T_BIAS_S / (T_BIAS_S + tau))
            assert np.sqrt(np.mean(part**2)) == pytest.approx(want_rms, rel=0.2)
        if j in (0, 3):  # the random-walk slope itself: N^2 at lags far below tau
            slope = float(np.mean(np.square(np.diff(x, axis=1)))) / step_s
            assert slope == pytest.approx(density**2, rel=0.1 + step_s / tau), CHANNELS[j]


def test_grades_name_their_units_and_rates() -> None:
    """Each INS grade names a real unit; no rate asked means the unit's datasheet output rate."""
    for key in ("tactical", "ellipse-d", "mems"):
        g = GRADES[key]
        assert g.name == key and g.unit
        m = measure_ins(_level, 0.0, 1.0, None, key, epoch_ns=EPOCH)
        assert np.all(np.diff(m.nav.t_ns) == round(1e9 / g.output_rate_hz))
        assert m.nav.pos_ned is None


def test_attitude_error_is_the_stated_rotation() -> None:
    g = GRADES["mems"]
    m = measure_ins(_truth, 0.0, 20.0, 100.0, g, seed=3, epoch_ns=EPOCH)
    tr = _truth((m.nav.t_ns - EPOCH) * 1e-9)
    # q_err = conj(q_true) * q_meas is the body-frame error rotation
    conj = tr.quat * np.array([1.0, -1.0, -1.0, -1.0])
    q_err = quat_multiply(conj, m.nav.quat)
    rotvec = 2.0 * q_err[:, 1:] * np.sign(q_err[:, :1])
    np.testing.assert_allclose(rotvec, m.att_error_rad, atol=1e-6)
    assert np.any(np.abs(m.att_error_rad) > 1e-3)


def test_gps_grade_position_and_rate() -> None:
    errs = []
    for seed in range(30):
        m = measure_ins(_level, 0.0, 5.0, 200.0, "gps", seed=seed, epoch_ns=EPOCH)
        assert np.all(np.diff(m.nav.t_ns) == 100_000_000)  # 10 Hz whatever the rate asked
        assert m.pos_error_ned is not None
        errs.append(np.linalg.norm(m.pos_error_ned[0]))
    # about 2 m absolute (3-D rms of the offset plus 0.3 m white noise)
    assert np.sqrt(np.mean(np.square(errs))) == pytest.approx(2.0, rel=0.3)


def test_clock_offset_and_drift() -> None:
    offset, ppm, rate = 0.0371, 40.0, 200.0
    dev, gps = device_ticks(-1.0, 10.0, rate, EPOCH, offset, ppm)
    assert np.all(np.diff(dev) == 5_000_000)  # uniform on the device clock
    t_gps = (gps - EPOCH) * 1e-9
    t_dev = (dev - EPOCH) * 1e-9
    np.testing.assert_allclose(t_dev, offset + t_gps * (1 + ppm * 1e-6), atol=1e-9)
    assert t_gps[0] >= -1.0 and t_gps[-1] <= 10.0 and t_gps[-1] > 10.0 - 1.0 / rate
    m = measure_ins(_truth, -1.0, 10.0, rate, "ideal", offset, ppm, epoch_ns=EPOCH)
    np.testing.assert_array_equal(m.t_device_ns, dev)
    np.testing.assert_array_equal(m.nav.t_ns, gps)
    # the GPS stamps drift against the device stamps by 40 us per second
    slope = np.polyfit(t_gps, (dev - gps) * 1e-9, 1)[0]
    assert slope == pytest.approx(ppm * 1e-6, rel=1e-3)


def test_bad_grade() -> None:
    with pytest.raises(ConfigError):
        measure_ins(_truth, 0.0, 1.0, 100.0, "nope")
    with pytest.raises(ConfigError):
        measure_ins(_truth, 1.0, 0.0, 100.0, InsGrade("x"))
    with pytest.raises(ConfigError, match="accuracy"):  # an accuracy no sensor error produces
        measure_ins(_truth, 0.0, 1.0, 100.0, InsGrade("x", vel_rms_mps=0.1))
