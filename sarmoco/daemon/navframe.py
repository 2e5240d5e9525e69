"""The one local frame of a store's positions.

``nav/pos_ned`` and ``motion/pos_ned`` are NED (m) in one frame per store: the frame the
first INS sample that names one gives (:attr:`~sarmoco.drivers.samples.VelocitySample.pos_frame`,
e.g. the autopilot's EKF origin, or the tangent plane at an SBG's first fix). A later
sample in another frame (an EKF origin stated after the first positions, a reset) has its
position re-expressed in the store's. The store states that frame in its root attribute
``geodetic_origin`` (:func:`~sarmoco.store.schema.encode_geodetic_origin`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from sarmoco.drivers.samples import TangentFrame, VelocitySample
from sarmoco.geodesy import geodetic_to_ned, ned_to_geodetic


class StoreFrame:
    """Keeps every sample's position in the first frame named (see the module docstring)."""

    def __init__(self) -> None:
        self.frame: TangentFrame | None = None
        """The store's frame (None until a sample names one)."""

    def express(self, sample: VelocitySample) -> VelocitySample:
        """``sample`` with its position in the store's frame (the first frame named sets it)."""
        named = sample.pos_frame
        if named is None or sample.pos_ned is None:
            return sample
        if self.frame is None:
            self.frame = named
        if named.lat_lon_alt == self.frame.lat_lon_alt:
            return sample
        lla = ned_to_geodetic(np.asarray(sample.pos_ned), named.lat_lon_alt)
        n, e, d = geodetic_to_ned(lla, self.frame.lat_lon_alt).tolist()
        return dataclasses.replace(sample, pos_ned=(n, e, d), pos_frame=self.frame)
