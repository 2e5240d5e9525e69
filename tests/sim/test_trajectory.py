"""True trajectory: consistent derivatives, turbulence matching its spectrum, flight-log motion."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.signal import welch
from scipy.spatial.transform import Rotation

from sarmoco.errors import ConfigError, NavigationError
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.trajectory import Trajectory, apc_trajectory, euler_to_quat, true_trajectory
from sarmoco.sim.turbulence import BAND_RATIO, lowpass2_psd
from tests.conftest import SHARED_DATA

TLOG = SHARED_DATA / "mavlink" / "arduplane_quadplane_sitl.tlog"

SPECS = {
    "ideal": MotionSpec(),
    "turbulence": MotionSpec(kind="turbulence", seed=7),
    "flightlog": MotionSpec(kind="flightlog", log_path=TLOG, log_start_s=30.0, log_window_s=10.0),
}


def _traj(kind: str, t: np.ndarray) -> Trajectory:
    return true_trajectory(load_preset("ku-vehicle", scale=0.1), t, SPECS[kind])


@pytest.mark.parametrize("kind", sorted(SPECS))
def test_derivatives_consistent(kind: str) -> None:
    dt = 2e-4
    tr = _traj(kind, np.arange(0.0, 2.0, dt))
    vel_num = np.gradient(tr.pos_ned, dt, axis=0)[2:-2]
    acc_num = np.gradient(tr.vel_ned, dt, axis=0)[2:-2]
    assert np.abs(vel_num - tr.vel_ned[2:-2]).max() < 1e-5
    assert np.abs(acc_num - tr.acc_ned[2:-2]).max() < 1e-3
    # trapezoidal integration of the velocity closes on the position (the INS-mocomp premise)
    steps = 0.5 * (tr.vel_ned[1:] + tr.vel_ned[:-1]) * dt
    integ = tr.pos_ned[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(steps, 0)])
    assert np.abs(integ - tr.pos_ned).max() < 1e-5
    assert np.allclose(np.linalg.norm(tr.quat, axis=1), 1.0)


def test_same_process_for_any_sampling() -> None:
    a = _traj("turbulence", np.array([0.1, 1.7, 3.3]))
    b = _traj("turbulence", np.linspace(0.0, 4.0, 401))
    np.testing.assert_allclose(a.pos_ned[1], b.pos_ned[170], atol=1e-12)
    c = true_trajectory(
        load_preset("ku-vehicle", scale=0.1),
        np.array([1.7]),
        MotionSpec(kind="turbulence", seed=8),
    )
    assert np.abs(c.pos_ned[0] - a.pos_ned[1]).max() > 1e-3


def test_turbulence_rms_and_spectrum() -> None:
    spec = MotionSpec(
        kind="turbulence",
        seed=11,
        cross_track_rms_m=0.4,
        vertical_rms_m=0.2,
        along_speed_rms_mps=0.15,
        attitude_rms_rad=0.02,
    )
    scn = load_preset("ku-vehicle", scale=0.1, lever_arm_m=(0.0, 0.0, 0.0))
    fs = 10.0
    t = np.arange(0.0, 1500.0, 1.0 / fs)
    tr = true_trajectory(scn, t, spec)
    ideal_pos, ideal_vel = scn.ideal_track(t)
    dev = tr.pos_ned - ideal_pos
    assert np.sqrt(np.mean(dev[:, 1] ** 2)) == pytest.approx(0.4, rel=0.1)
    assert np.sqrt(np.mean(dev[:, 2] ** 2)) == pytest.approx(0.2, rel=0.1)
    assert np.std(tr.vel_ned[:, 0] - ideal_vel[:, 0]) == pytest.approx(0.15, rel=0.1)
    # roll from the quaternion (3-2-1): atan2(2(wx + yz), 1 - 2(x^2 + y^2))
    w, x, y, z = tr.quat.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x**2 + y**2))
    assert np.sqrt(np.mean(roll**2)) == pytest.approx(0.02, rel=0.1)
    # power per octave band (Welch) against the documented spectrum's share of that band
    f, pxx = welch(dev[:, 1], fs=fs, nperseg=2**13)
    fine = np.geomspace(spec.corner_hz / BAND_RATIO, spec.corner_hz * BAND_RATIO, 20001)
    s_model = lowpass2_psd(fine, spec.corner_hz)
    total = np.trapezoid(s_model, fine)
    edges = spec.corner_hz * 2.0 ** np.arange(-3, 4)
    measured, expected = [], []
    for lo, hi in itertools.pairwise(edges):
        b, m = (f >= lo) & (f < hi), (fine >= lo) & (fine < hi)
        measured.append(np.sum(pxx[b]) * (f[1] - f[0]))
        expected.append(0.4**2 * np.trapezoid(s_model[m], fine[m]) / total)
    ratio_db = 10 * np.log10(np.array(measured) / np.array(expected))
    # the expected band powers fall by 14 dB across these six octaves; each is met to 1 dB
    # (measured worst 0.6 dB)
    assert 10 * np.log10(expected[0] / expected[-1]) > 12
    assert np.abs(ratio_db).max() < 1.0, ratio_db


def test_flightlog_is_real_motion() -> None:
    scn = load_preset("ku-vehicle", scale=0.1, lever_arm_m=(0.0, 0.0, 0.0))
    tr = true_trajectory(scn, np.arange(0.0, 10.0, 0.01), SPECS["flightlog"])
    ideal, _ = scn.ideal_track(tr.t_s)
    dev = tr.pos_ned - ideal
    assert np.allclose(dev[0], 0.0)
    assert 0.005 < np.std(dev[:, 1]) < 5.0 and 0.005 < np.std(dev[:, 2]) < 5.0
    assert np.std(tr.acc_ned[:, 2]) > 1e-3
    with pytest.raises(NavigationError):
        _traj("flightlog", np.array([0.0, 30.0]))
    with pytest.raises(ConfigError):
        true_trajectory(
            scn, np.zeros(1), MotionSpec(kind="flightlog", log_path=TLOG, log_start_s=0.0)
        )
    with pytest.raises(ConfigError):
        true_trajectory(scn, np.zeros(1), MotionSpec(kind="flightlog"))


def test_euler_to_quat_convention() -> None:
    q = euler_to_quat(np.array([[0.0, 0.0, np.pi / 2]]))[0]
    # yaw +90 deg rotates body x (forward) onto NED east
    w, x, y, z = q
    rot_x = np.array([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])
    np.testing.assert_allclose(rot_x, [0.0, 1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("heading_deg", [0.0, 130.0])
def test_the_antenna_sits_the_rotated_lever_arm_from_the_ins(heading_deg: float) -> None:
    """APC = INS point + R(q) l, its velocity the INS's plus the arm's rate; at level
    attitude the APC flies the nominal line (the scenario's altitude is the antenna's)."""
    arm = (0.3, -0.2, 0.25)
    scn = load_preset("ku-vehicle", 0.1, lever_arm_m=arm, heading_rad=math.radians(heading_deg))
    t = np.linspace(0.0, 3.0, 301)
    level = apc_trajectory(scn, t, MotionSpec())
    ideal, ideal_vel = scn.ideal_track(t)
    np.testing.assert_allclose(level.pos_ned, ideal, atol=1e-9)
    np.testing.assert_allclose(level.vel_ned, ideal_vel, atol=1e-6)
    spec = MotionSpec(kind="turbulence", seed=3, attitude_rms_rad=0.05)
    imu, apc = true_trajectory(scn, t, spec), apc_trajectory(scn, t, spec)
    r = Rotation.from_quat(imu.quat[:, [1, 2, 3, 0]])
    np.testing.assert_allclose(apc.pos_ned - imu.pos_ned, r.apply(arm), atol=1e-12)
    rate = np.gradient(r.apply(arm), t, axis=0)
    inner = slice(1, -1)
    np.testing.assert_allclose((apc.vel_ned - imu.vel_ned)[inner], rate[inner], atol=2e-4)
    assert np.ptp(np.linalg.norm(apc.pos_ned - imu.pos_ned - r.apply(arm), axis=1)) < 1e-12
