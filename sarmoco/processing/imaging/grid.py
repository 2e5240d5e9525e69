"""Pixel grids on a horizontal plane, shared by backprojection and polar format.

A :class:`PlaneGrid` lives in any right-handed Cartesian frame whose third axis
is vertical (the imaging frame of docs/methods.md §1 with z down, NED, or a provider's
scene frame with z up). Pixel ``(i, j)`` sits at
``origin + axis0[i] * e0 + axis1[j] * e1`` with the horizontal unit vectors
``e0 = (cos h, sin h, 0)`` and ``e1 = (-sin h, cos h, 0)``, ``h`` the heading
of axis 0 measured from the frame's x axis toward its y axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import FloatArray


@dataclass(frozen=True)
class PlaneGrid:
    """A rectangular pixel grid on the plane through ``origin_m`` normal to the frame's z.

    Parameters
    ----------
    axis0_m, axis1_m : ndarray of float64
        Pixel-centre coordinates along ``e0`` and ``e1``, m, uniformly spaced.
    origin_m : tuple of float
        Frame coordinates of the point ``axis0 = axis1 = 0``, m (its z is the
        plane's height coordinate).
    heading_rad : float
        Angle of ``e0`` from the frame's x axis toward its y axis, rad.
    frame : str
        Name stored in the resulting :class:`~sarmoco.processing.types.Image`.
    """

    axis0_m: FloatArray
    axis1_m: FloatArray
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    heading_rad: float = 0.0
    frame: str = "ground"

    def __post_init__(self) -> None:
        for name in ("axis0_m", "axis1_m"):
            ax = np.asarray(getattr(self, name), dtype=np.float64)
            if ax.ndim != 1 or ax.shape[0] < 2:
                raise ProcessingError(f"PlaneGrid.{name}: need a 1-D axis of >= 2 pixels")
            step = np.diff(ax)
            if not np.allclose(step, step[0], rtol=1e-9, atol=0.0) or step[0] == 0:
                raise ProcessingError(f"PlaneGrid.{name}: not uniformly spaced")

    @classmethod
    def centred(
        cls,
        centre_m: tuple[float, float, float],
        n0: int,
        n1: int,
        spacing0_m: float,
        spacing1_m: float,
        heading_rad: float = 0.0,
        frame: str = "ground",
    ) -> PlaneGrid:
        """A grid of ``n0 x n1`` pixels whose centre pixel is ``centre_m`` (the origin)."""
        ax0 = (np.arange(n0) - n0 // 2).astype(np.float64) * spacing0_m
        ax1 = (np.arange(n1) - n1 // 2).astype(np.float64) * spacing1_m
        return cls(ax0, ax1, centre_m, heading_rad, frame)

    @property
    def unit_vectors(self) -> tuple[FloatArray, FloatArray]:
        """(e0, e1): horizontal unit vectors of axis 0 and axis 1 in the frame."""
        c, s = np.cos(self.heading_rad), np.sin(self.heading_rad)
        return np.array([c, s, 0.0]), np.array([-s, c, 0.0])

    def positions(self) -> FloatArray:
        """Frame coordinates of every pixel, shape (n0, n1, 3), m."""
        e0, e1 = self.unit_vectors
        a0 = np.asarray(self.axis0_m, dtype=np.float64)[:, None, None]
        a1 = np.asarray(self.axis1_m, dtype=np.float64)[None, :, None]
        return np.asarray(np.asarray(self.origin_m, dtype=np.float64) + a0 * e0 + a1 * e1)


def facing_heading(apc_m: FloatArray, centre_m: tuple[float, float, float]) -> float:
    """Heading that makes a grid's axis 1 the mean horizontal look direction (radar to scene).

    Parameters
    ----------
    apc_m : ndarray of float64, shape (P, 3)
        Antenna phase centres, m.
    centre_m : tuple of float
        Scene centre, m.

    Returns
    -------
    float
        ``heading_rad`` for :class:`PlaneGrid`: ``e1`` along the mean of the
        horizontal unit vectors from the APCs to the centre, ``e0`` 90° to its right
        when seen from above with z up (for a radar looking right along a track
        in NED, ``e0`` is the direction of flight).
    """
    look = np.asarray(centre_m, dtype=np.float64)[None, :2] - apc_m[:, :2]
    look /= np.linalg.norm(look, axis=1)[:, None]
    mean = look.mean(axis=0)
    # e1 = (-sin h, cos h) = mean look
    return float(np.arctan2(-mean[0], mean[1]))
