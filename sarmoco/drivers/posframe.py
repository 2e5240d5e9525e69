"""Geodetic INS positions as local NED, in one stated frame per source.

An INS gives its position as latitude, longitude and altitude (SBG EKF_NAV, MAVLink
GLOBAL_POSITION_INT), as NED about a point it states (MAVLink LOCAL_POSITION_NED about
the EKF origin of GPS_GLOBAL_ORIGIN), or both. :class:`LocalPositions` turns each into
the other and names the frame (:class:`~sarmoco.drivers.samples.TangentFrame`): the
INS's own when it states one, otherwise the tangent plane at the first position received.
"""

from __future__ import annotations

import numpy as np

from sarmoco.drivers.samples import TangentFrame
from sarmoco.geodesy import geodetic_to_ned, ned_to_geodetic

Vec3 = tuple[float, float, float]


class LocalPositions:
    """The frame of one source's local positions, and the conversions into and out of it.

    Parameters
    ----------
    first_fix_source : str
        ``source`` of the frame taken from the first geodetic position when the INS
        states none (e.g. ``"sbg.EKF_NAV"``).
    ellipsoid_height : bool
        The source's altitudes are heights above the WGS-84 ellipsoid
        (:attr:`TangentFrame.ellipsoid_height`).
    """

    def __init__(self, first_fix_source: str, ellipsoid_height: bool = False) -> None:
        self._first_fix_source = first_fix_source
        self._ellipsoid_height = ellipsoid_height
        self.stated: TangentFrame | None = None
        """The frame the INS states for its local positions (None until it does)."""
        self.first_fix: TangentFrame | None = None
        """The tangent plane at the first geodetic position received."""

    @property
    def frame(self) -> TangentFrame | None:
        """The frame geodetic positions are turned into: the stated one, else the first fix's."""
        return self.stated if self.stated is not None else self.first_fix

    def state(self, lat_lon_alt: Vec3, source: str) -> None:
        """The INS states the origin of its local frame (deg, deg, m)."""
        if self.stated is None or self.stated.lat_lon_alt != lat_lon_alt:
            self.stated = TangentFrame(lat_lon_alt, source, self._ellipsoid_height, stated=True)

    def local(self, lat_lon_alt: Vec3) -> tuple[Vec3, TangentFrame]:
        """A geodetic position (deg, deg, m) as NED (m) in :attr:`frame`, and that frame."""
        if self.frame is None:
            self.first_fix = TangentFrame(
                lat_lon_alt, self._first_fix_source, self._ellipsoid_height
            )
        frame = self.frame
        assert frame is not None
        n, e, d = geodetic_to_ned(np.asarray(lat_lon_alt), frame.lat_lon_alt).tolist()
        return (n, e, d), frame

    def geodetic(self, ned: Vec3) -> Vec3 | None:
        """A local NED position (m) in the stated frame as latitude, longitude (deg) and
        altitude (m); None while the INS has stated no frame."""
        if self.stated is None:
            return None
        lat, lon, alt = ned_to_geodetic(np.asarray(ned), self.stated.lat_lon_alt).tolist()
        return (lat, lon, alt)
