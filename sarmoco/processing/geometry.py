"""Frames of docs/methods.md §1: NED, the imaging frame, look angle and lever arm.

The imaging frame has its origin at the reference antenna phase centre (APC)
at the first pulse of the aperture; **x** is the horizontal unit vector of the
mean ground velocity (or a configured heading), **y** is horizontal and
perpendicular to x, pointing to the illuminated side, **z** is down. The
reference track is the straight line through the origin along x at the mean
along-track speed ``v0``. For a right-looking radar the frame is right-handed
(x, y, z = along, right, down); for a left-looking one y points left.

Quaternions are scalar-first ``[w, x, y, z]`` and rotate body vectors into NED
(body x forward, y right wing, z down). Times are GPS ns (``int64``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import FloatArray, IntArray

LookSide = Literal["right", "left"]

_DOWN = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class ReferenceTrack:
    """Straight, horizontal reference track of one aperture.

    Parameters
    ----------
    origin_ned : ndarray of float64, shape (3,)
        Reference APC at the first pulse (imaging-frame origin), NED, m.
    x_hat, y_hat : ndarray of float64, shape (3,)
        Imaging-frame x (along track) and y (toward the illuminated side)
        unit vectors expressed in NED; both horizontal.
    v0_mps : float
        Along-track speed of the reference track, m/s.
    t0_ns : int
        GPS time at which the reference APC is at the origin, ns.
    """

    origin_ned: FloatArray
    x_hat: FloatArray
    y_hat: FloatArray
    v0_mps: float
    t0_ns: int

    @classmethod
    def from_velocity(
        cls,
        origin_ned: FloatArray,
        velocity_ned: FloatArray,
        t0_ns: int,
        look_side: LookSide = "right",
    ) -> ReferenceTrack:
        """Build the track through ``origin_ned`` along the horizontal part of a velocity.

        Parameters
        ----------
        origin_ned : ndarray, shape (3,)
            Reference APC at ``t0_ns``, NED, m.
        velocity_ned : ndarray, shape (3,)
            Mean (or configured) velocity, NED, m/s; only north and east are used.
        t0_ns : int
            GPS time of the origin, ns.
        look_side : {"right", "left"}
            Side the antenna illuminates, seen from above along the track.
        """
        ground = np.array([velocity_ned[0], velocity_ned[1], 0.0], dtype=np.float64)
        v0 = float(np.hypot(ground[0], ground[1]))
        if not v0 > 0.0:
            raise ProcessingError(f"reference track: ground speed {v0!r} m/s is not > 0")
        if look_side not in ("right", "left"):
            raise ProcessingError(f"reference track: look_side {look_side!r} is not right/left")
        x_hat = ground / v0
        y_hat = np.cross(_DOWN, x_hat)
        if look_side == "left":
            y_hat = -y_hat
        return cls(
            origin_ned=np.asarray(origin_ned, dtype=np.float64).copy(),
            x_hat=x_hat,
            y_hat=y_hat,
            v0_mps=v0,
            t0_ns=int(t0_ns),
        )

    @property
    def rotation(self) -> FloatArray:
        """Matrix (3, 3) whose rows are x_hat, y_hat, z_hat: ``v_img = rotation @ v_ned``."""
        return np.stack([self.x_hat, self.y_hat, _DOWN])

    def position_imaging(self, t_ns: IntArray) -> FloatArray:
        """Reference APC at times ``t_ns`` in the imaging frame, (P, 3), m."""
        along = self.v0_mps * (np.asarray(t_ns, dtype=np.int64) - self.t0_ns) * 1e-9
        out = np.zeros((along.shape[0], 3))
        out[:, 0] = along
        return out

    def position_ned(self, t_ns: IntArray) -> FloatArray:
        """Reference APC at times ``t_ns`` in NED, (P, 3), m."""
        return imaging_to_ned(self.position_imaging(t_ns), self)

    def deviation(self, t_ns: IntArray, pos_ned: FloatArray) -> FloatArray:
        """Actual minus reference APC at the same times, imaging frame, (P, 3), m.

        Columns are (Δx, Δy, Δz); Δy, Δz are the cross-track and vertical
        deviations that docs/methods.md §1 projects on the line of sight.
        """
        return ned_to_imaging(pos_ned, self) - self.position_imaging(t_ns)


def _mean_ground_velocity_from_positions(t_ns: IntArray, pos_ned: FloatArray) -> FloatArray:
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    if t.shape[0] < 2 or not t[-1] > 0.0:
        raise ProcessingError("reference track: need at least two distinct times")
    design = np.stack([np.ones_like(t), t], axis=1)
    coef, *_ = np.linalg.lstsq(design, np.asarray(pos_ned, dtype=np.float64), rcond=None)
    return np.asarray(coef[1], dtype=np.float64)


def fit_reference_track(
    t_ns: IntArray, pos_ned: FloatArray, look_side: LookSide = "right"
) -> ReferenceTrack:
    """Reference track of an aperture from APC positions.

    The mean ground velocity is the least-squares slope of position against
    time (robust to position noise); the origin is the first position.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse (or sample) times, GPS ns.
    pos_ned : ndarray of float64, shape (P, 3)
        APC positions, NED, m.
    look_side : {"right", "left"}
        Illuminated side.
    """
    pos = np.asarray(pos_ned, dtype=np.float64)
    vel = _mean_ground_velocity_from_positions(t_ns, pos)
    return ReferenceTrack.from_velocity(pos[0], vel, int(t_ns[0]), look_side)


def reference_track_from_velocity(
    t_ns: IntArray,
    vel_ned: FloatArray,
    origin_ned: FloatArray | None = None,
    look_side: LookSide = "right",
) -> ReferenceTrack:
    """Reference track of an aperture from velocities only (INS-only processing).

    The mean velocity is the trapezoidal time average of ``vel_ned`` over the
    (possibly non-uniform) times; the origin defaults to NED zero, i.e. the
    imaging frame is anchored at the APC of the first pulse.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Times, GPS ns.
    vel_ned : ndarray of float64, shape (P, 3)
        APC velocity, NED, m/s.
    origin_ned : ndarray, shape (3,), optional
        APC at ``t_ns[0]``, NED, m.
    look_side : {"right", "left"}
        Illuminated side.
    """
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    if t.shape[0] < 2 or not t[-1] > 0.0:
        raise ProcessingError("reference track: need at least two distinct times")
    vel = np.asarray(vel_ned, dtype=np.float64)
    mean = np.trapezoid(vel, t, axis=0) / t[-1]
    origin = np.zeros(3) if origin_ned is None else np.asarray(origin_ned, dtype=np.float64)
    return ReferenceTrack.from_velocity(origin, mean, int(t_ns[0]), look_side)


def vector_to_imaging(vec_ned: FloatArray, track: ReferenceTrack) -> FloatArray:
    """Rotate free vectors (velocities, offsets) from NED into the imaging frame, (..., 3)."""
    return np.asarray(vec_ned, dtype=np.float64) @ track.rotation.T


def ned_to_imaging(pos_ned: FloatArray, track: ReferenceTrack) -> FloatArray:
    """Positions from NED to the imaging frame (translate to the origin, rotate), (..., 3), m."""
    return vector_to_imaging(np.asarray(pos_ned, dtype=np.float64) - track.origin_ned, track)


def imaging_to_ned(pos_img: FloatArray, track: ReferenceTrack) -> FloatArray:
    """Positions from the imaging frame back to NED, (..., 3), m.

    The rotation is orthogonal (rows are orthonormal), so its inverse is its transpose.
    """
    return np.asarray(pos_img, dtype=np.float64) @ track.rotation + track.origin_ned


def look_angle(slant_range_m: FloatArray | float, depth_m: float) -> FloatArray:
    """Off-nadir look angle over flat ground, cos β = H / r (docs/methods.md §1).

    Parameters
    ----------
    slant_range_m : float or ndarray
        Slant range of each range bin, m.
    depth_m : float
        Depth of the flat ground below the reference track, m (> 0).

    Returns
    -------
    ndarray of float64
        β, rad, same shape as ``slant_range_m``.

    Raises
    ------
    ProcessingError
        If ``depth_m`` is not positive or a range is shorter than ``depth_m``
        (such a bin does not meet the ground).
    """
    r = np.asarray(slant_range_m, dtype=np.float64)
    if not depth_m > 0.0:
        raise ProcessingError(f"look_angle: depth {depth_m!r} m is not > 0")
    if np.any(r < depth_m):
        raise ProcessingError(
            f"look_angle: slant range {float(r.min())!r} m is shorter than the depth {depth_m!r} m"
        )
    return np.asarray(np.arccos(depth_m / r), dtype=np.float64)


def los_unit(beta_rad: FloatArray | float) -> FloatArray:
    """Imaging-frame unit vector from the APC to a broadside target, (0, sin β, cos β), (..., 3)."""
    b = np.asarray(beta_rad, dtype=np.float64)
    return np.stack([np.zeros_like(b), np.sin(b), np.cos(b)], axis=-1)


def quat_to_matrix(quat: FloatArray) -> FloatArray:
    """Rotation matrices (..., 3, 3) of scalar-first body-to-NED quaternions (..., 4).

    The quaternions are normalised first.
    """
    q = np.asarray(quat, dtype=np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ProcessingError("quat_to_matrix: zero quaternion")
    w, x, y, z = np.moveaxis(q / norm, -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def body_heading_rad(quat: FloatArray) -> FloatArray:
    """Heading of the body's x axis of scalar-first body-to-NED quaternions (P, 4), rad from
    north toward east (P,); NaN where the quaternion is not finite or is zero."""
    q = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    ok = np.all(np.isfinite(q), axis=1) & (np.linalg.norm(q, axis=1) > 0.0)
    out = np.full(q.shape[0], np.nan)
    if ok.any():
        x_ned = quat_to_matrix(q[ok])[:, :, 0]
        out[ok] = np.arctan2(x_ned[:, 1], x_ned[:, 0])
    return out


def lever_arm_ned(quat: FloatArray, lever_body_m: FloatArray) -> FloatArray:
    """IMU-to-APC lever arm rotated into NED by the attitude, (..., 3), m.

    Parameters
    ----------
    quat : ndarray, shape (..., 4)
        Attitude, scalar-first body-to-NED quaternions.
    lever_body_m : ndarray, shape (3,)
        APC minus IMU position in the body frame (x forward, y right, z down), m.
    """
    return quat_to_matrix(quat) @ np.asarray(lever_body_m, dtype=np.float64)


def apply_lever_arm(pos_ned: FloatArray, quat: FloatArray, lever_body_m: FloatArray) -> FloatArray:
    """APC position from the IMU position and attitude: ``pos + R(q) l``, (P, 3), NED, m."""
    return np.asarray(pos_ned, dtype=np.float64) + lever_arm_ned(quat, lever_body_m)
