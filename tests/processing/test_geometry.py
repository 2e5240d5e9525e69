"""Frames, reference track, look angle and lever arm (docs/methods.md §1)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sarmoco.errors import ProcessingError
from sarmoco.processing.geometry import (
    ReferenceTrack,
    apply_lever_arm,
    fit_reference_track,
    imaging_to_ned,
    lever_arm_ned,
    look_angle,
    los_unit,
    ned_to_imaging,
    quat_to_matrix,
    reference_track_from_velocity,
    vector_to_imaging,
)


def _quat_ypr(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Scalar-first body-to-NED quaternion of a 3-2-1 (yaw, pitch, roll) attitude."""
    rot = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    return np.asarray(rot.as_quat(scalar_first=True))


@pytest.mark.parametrize(
    ("vel", "side", "y_expected"),
    [
        ((60.0, 0.0, 0.0), "right", (0.0, 1.0, 0.0)),  # north, looking east
        ((60.0, 0.0, 0.0), "left", (0.0, -1.0, 0.0)),  # north, looking west
        ((0.0, -30.0, 2.0), "right", (1.0, 0.0, 0.0)),  # west (climbing), looking north
    ],
)
def test_axes_point_along_track_and_to_the_illuminated_side(
    vel: tuple[float, float, float], side: str, y_expected: tuple[float, float, float]
) -> None:
    track = ReferenceTrack.from_velocity(np.zeros(3), np.array(vel), 0, side)  # type: ignore[arg-type]
    np.testing.assert_allclose(track.y_hat, y_expected, atol=1e-15)
    assert track.v0_mps == pytest.approx(np.hypot(vel[0], vel[1]))
    np.testing.assert_allclose(track.rotation @ track.rotation.T, np.eye(3), atol=1e-15)


def test_ned_imaging_round_trip_and_reference_line() -> None:
    rng = np.random.default_rng(1)
    track = ReferenceTrack.from_velocity(
        np.array([100.0, -20.0, -1000.0]), np.array([40.0, 45.0, 0.3]), 5_000_000_000
    )
    pts = rng.normal(scale=500.0, size=(50, 3))
    np.testing.assert_allclose(imaging_to_ned(ned_to_imaging(pts, track), track), pts, atol=1e-9)
    t = track.t0_ns + np.arange(0, 1_000_000_000, 100_000_000, dtype=np.int64)
    ref = track.position_ned(t)
    np.testing.assert_allclose(track.deviation(t, ref), 0.0, atol=1e-9)
    img = ned_to_imaging(ref, track)
    np.testing.assert_allclose(img[:, 0], track.v0_mps * (t - track.t0_ns) * 1e-9, rtol=1e-12)
    # a 1 m offset to the illuminated side and 0.5 m down shows up as (Δy, Δz)
    dev = track.deviation(t, ref + track.y_hat + 0.5 * np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(dev, np.tile([0.0, 1.0, 0.5], (t.shape[0], 1)), atol=1e-9)
    vel_img = vector_to_imaging(np.array([40.0, 45.0, 0.3]), track)
    np.testing.assert_allclose(vel_img, [track.v0_mps, 0.0, 0.3], atol=1e-12)


def test_fit_reference_track_recovers_mean_ground_velocity_from_noisy_positions() -> None:
    rng = np.random.default_rng(2)
    t_ns = np.sort(rng.integers(0, 4_000_000_000, size=400)).astype(np.int64)
    t_ns[0] = 0
    vel = np.array([-12.0, 59.0, -0.5])
    pos = np.array([10.0, 20.0, -900.0]) + np.outer(t_ns * 1e-9, vel)
    pos_noisy = pos + rng.normal(scale=0.05, size=pos.shape)
    track = fit_reference_track(t_ns, pos_noisy)
    heading = np.arctan2(vel[1], vel[0])
    assert np.arctan2(track.x_hat[1], track.x_hat[0]) == pytest.approx(heading, abs=1e-3)
    assert track.v0_mps == pytest.approx(np.hypot(vel[0], vel[1]), rel=1e-3)
    np.testing.assert_array_equal(track.origin_ned, pos_noisy[0])
    # from velocities (trapezoid mean over non-uniform times): exact for a linear velocity
    acc = np.array([0.2, 0.0, 0.0])
    v_lin = vel + np.outer(t_ns * 1e-9, acc)
    tv = reference_track_from_velocity(t_ns, v_lin)
    mean = vel + acc * t_ns[-1] * 1e-9 / 2
    assert tv.v0_mps == pytest.approx(np.hypot(mean[0], mean[1]), rel=1e-12)
    np.testing.assert_array_equal(tv.origin_ned, 0.0)
    with pytest.raises(ProcessingError):
        fit_reference_track(t_ns[:1], pos[:1])
    with pytest.raises(ProcessingError):
        ReferenceTrack.from_velocity(np.zeros(3), np.array([0.0, 0.0, 5.0]), 0)


def test_look_angle_and_los_unit_reach_a_broadside_ground_target() -> None:
    depth = 1000.0
    ground_y = np.array([200.0, 1118.0, 3000.0])
    r = np.hypot(ground_y, depth)
    beta = look_angle(r, depth)
    np.testing.assert_allclose(np.cos(beta), depth / r, rtol=1e-14)
    target = np.stack([np.zeros(3), ground_y, np.full(3, depth)], axis=1)
    np.testing.assert_allclose(np.sum(los_unit(beta) * target, axis=1), r, rtol=1e-12)
    assert look_angle(1500.0, 1000.0).shape == ()
    with pytest.raises(ProcessingError):
        look_angle(np.array([999.0, 1500.0]), depth)
    with pytest.raises(ProcessingError):
        look_angle(1500.0, 0.0)


def test_quaternion_matrix_matches_scipy_and_lever_arm_follows_attitude() -> None:
    rng = np.random.default_rng(3)
    angles = rng.uniform(-np.pi / 2, np.pi / 2, size=(20, 3))
    quat = np.array([_quat_ypr(*a) for a in angles])
    expect = Rotation.from_quat(quat, scalar_first=True).as_matrix()
    np.testing.assert_allclose(quat_to_matrix(quat), expect, atol=1e-14)
    # yaw 90°: the nose points east; a lever 1 m forward, 0.2 m down lands 1 m east, 0.2 m down
    q_east = _quat_ypr(np.pi / 2, 0.0, 0.0)
    np.testing.assert_allclose(
        lever_arm_ned(q_east, np.array([1.0, 0.0, 0.2])), [0.0, 1.0, 0.2], atol=1e-15
    )
    # roll 90° right wing down: the body y axis (right wing) points down
    q_roll = _quat_ypr(0.0, 0.0, np.pi / 2)
    pos = apply_lever_arm(np.array([[1.0, 2.0, 3.0]]), q_roll[None, :], np.array([0.0, 0.5, 0.0]))
    np.testing.assert_allclose(pos, [[1.0, 2.0, 3.5]], atol=1e-15)
    with pytest.raises(ProcessingError):
        quat_to_matrix(np.zeros(4))
