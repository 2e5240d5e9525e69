"""What is made from a recorded store on the ground: the run report and its quicklooks,
the array report, georeferencing, north-up images, GeoTIFF, SICD, CPHD and CRSD.

Products read a store (:mod:`sarmoco.store`) and use processing for the physics; the
daemon never imports them, so the process that flies loads none of this.

``__all__`` lists the modules other packages use; the rest are internal to this one.
"""

__all__ = [
    "array_report",
    "cphd",
    "crsd",
    "georeference",
    "geotiff",
    "northup",
    "report",
    "sicd",
]
