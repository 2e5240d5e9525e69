"""INS measurement model: noise, bias and drift statistics, attitude errors, clock mapping."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from sarmoco.errors import ConfigError
from sarmoco.processing.types import FloatArray
from sarmoco.sim.ins import GRADES, InsGrade, device_ticks, measure_ins, quat_multiply
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.trajectory import MotionSpec, Trajectory, true_trajectory

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


@pytest.mark.parametrize("grade", ["tactical", "mems"])
def test_velocity_error_statistics(grade: str) -> None:
    g = GRADES[grade]
    rate, dur = 200.0, 25.0
    biases, walks, noise = [], [], []
    for seed in range(40):
        m = measure_ins(_level, 0.0, dur, rate, grade, seed=seed, epoch_ns=EPOCH)
        biases.append(m.vel_bias_ned[0])
        walks.append(m.vel_bias_ned[-1] - m.vel_bias_ned[0])
        noise.append(np.std(m.vel_error_ned - m.vel_bias_ned, axis=0))
        assert m.nav.pos_ned is None
    # turn-on bias: std over realisations and axes (120 draws: +-13 % at 2 sigma)
    assert np.std(biases) == pytest.approx(g.vel_bias_mps, rel=0.2)
    # random walk: std after T seconds is q sqrt(T)
    assert np.std(walks) == pytest.approx(g.vel_bias_drift_mps_per_sqrt_s * math.sqrt(dur), rel=0.2)
    # white part per sample
    assert np.mean(noise) == pytest.approx(g.vel_noise_mps, rel=0.02)


def test_attitude_error_is_the_stated_rotation() -> None:
    g = GRADES["mems"]
    m = measure_ins(_truth, 0.0, 20.0, 100.0, g, seed=3, epoch_ns=EPOCH)
    tr = _truth((m.nav.t_ns - EPOCH) * 1e-9)
    # q_err = conj(q_true) * q_meas is the body-frame error rotation
    conj = tr.quat * np.array([1.0, -1.0, -1.0, -1.0])
    q_err = quat_multiply(conj, m.nav.quat)
    rotvec = 2.0 * q_err[:, 1:] * np.sign(q_err[:, :1])
    np.testing.assert_allclose(rotvec, m.att_error_rad, atol=1e-6)
    assert np.std(m.att_error_rad - m.att_error_rad.mean(0)) == pytest.approx(
        g.att_noise_rad, rel=0.05
    )


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
        measure_ins(_truth, 1.0, 0.0, 100.0, InsGrade("x", 0, 0, 0, 0, 0))
