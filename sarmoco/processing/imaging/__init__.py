"""Image formation: range-Doppler (stripmap), polar format (spotlight), backprojection.

Each imager returns a :class:`sarmoco.processing.types.Image` with its grid.
"""

from sarmoco.processing.imaging.backprojection import backproject
from sarmoco.processing.imaging.grid import PlaneGrid, facing_heading
from sarmoco.processing.imaging.pfa import PfaSupport, pfa_support, polar_format, validity_radius_m
from sarmoco.processing.imaging.phase_history import (
    compressed_from_phase_history,
    phase_history_from_compressed,
)
from sarmoco.processing.imaging.rda import range_doppler

__all__ = [
    "PfaSupport",
    "PlaneGrid",
    "backproject",
    "backprojection",
    "compressed_from_phase_history",
    "facing_heading",
    "ffbp",
    "grid",
    "interp",
    "pfa_support",
    "phase_history",
    "phase_history_from_compressed",
    "polar_format",
    "presum",
    "range_doppler",
    "rda_tiles",
    "tile_pga",
    "tiles",
    "validity_radius_m",
]
