"""MIMO downward-looking array: geometry, roll compensation, 3-D imaging, DEM evaluation.

Imports only numpy/scipy, :mod:`sarmoco.processing` and :mod:`sarmoco.errors`
(docs/methods.md §4).


``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "dem",
    "geometry",
    "imaging3d",
]
