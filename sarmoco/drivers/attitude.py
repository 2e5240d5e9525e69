"""Attitude conversions shared by the drivers (no dependency on processing).

Quaternions are scalar-first ``(w, x, y, z)`` and rotate body-frame vectors into
NED; Euler angles are the aerospace 3-2-1 sequence (yaw about down, then pitch,
then roll), radians.
"""

from __future__ import annotations

import math


def euler_to_quat(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """3-2-1 Euler angles (rad) → unit quaternion ``(w, x, y, z)``, body → NED."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def quat_to_euler(q: tuple[float, float, float, float]) -> tuple[float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` → 3-2-1 Euler angles (roll, pitch, yaw), rad."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def normalized(q: tuple[float, ...]) -> tuple[float, float, float, float] | None:
    """``q`` scaled to unit norm, or None when its norm is not finite and positive."""
    n = math.sqrt(sum(c * c for c in q))
    if not (math.isfinite(n) and n > 1e-6) or len(q) != 4:
        return None
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
