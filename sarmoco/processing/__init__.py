"""Pure numpy/scipy signal processing: no I/O, no threads, no imports of daemon, drivers or sim.

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "array",
    "autofocus",
    "beam",
    "geometry",
    "imaging",
    "metrics",
    "mocomp",
    "navinterp",
    "phasor",
    "rangecomp",
    "segments",
    "types",
]
