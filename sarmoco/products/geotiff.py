"""A georeferenced quicklook: GeoTIFF of each reference-track segment, for a GIS.

Written with tifffile (pure Python, no system GDAL): 8-bit gray in dB as the PNG quicklook
draws it (:func:`~sarmoco.grayscale.gray_db`, full resolution: along track to the
right, far range at the top), with the GeoTIFF tags a GIS reads: ModelTransformationTag
(an affine map from raster to longitude and latitude, WGS-84; the grid is a rotated
rectangle on the ground, so the map has rotation terms) and GeoKeyDirectoryTag
(geographic model, pixel-is-area, EPSG:4326). The affine map is fitted to every pixel's
position from :mod:`sarmoco.products.georeference`; its largest residual is returned.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tifffile

from sarmoco.grayscale import gray_db
from sarmoco.processing.types import FloatArray
from sarmoco.products.georeference import georeference, grid_points, segment_images
from sarmoco.store.reader import RunStore

MODEL_TRANSFORMATION_TAG = 34264
GEO_KEY_DIRECTORY_TAG = 34735
_GEO_KEYS = (
    (1, 1, 0, 3),  # version 1.1.0, three keys
    (1024, 0, 1, 2),  # GTModelTypeGeoKey: geographic
    (1025, 0, 1, 1),  # GTRasterTypeGeoKey: pixel is area
    (2048, 0, 1, 4326),  # GeographicTypeGeoKey: WGS 84
)


@dataclass(frozen=True)
class GeoTiff:
    """One GeoTIFF written.

    Attributes
    ----------
    path : Path
        The file.
    transform : ndarray, shape (2, 3)
        ``[lon, lat] = transform @ [column, row, 1]`` (raster corner coordinates, deg).
    max_residual_m : float
        Largest distance between a pixel centre's position and the affine map's, m.
    """

    path: Path
    transform: FloatArray
    max_residual_m: float


def write_geotiffs(store: RunStore, out_dir: Path) -> list[GeoTiff]:
    """``image_geo_KK.tif`` in ``out_dir`` for each reference-track segment ``KK``.

    Raises
    ------
    RecorderError
        The store has no absolute position, or an image not in the ground plane.
    """
    from sarmoco.daemon.config import parse_config

    geo = georeference(store)
    depth = parse_config(store.attrs["config"]).geometry.height_m
    written = []
    for k, seg in enumerate(segment_images(store)):
        n0, n1 = seg.image.data.shape
        lla = geo.geodetic(grid_points(seg.image, seg.track, depth))  # (n0, n1, 3)
        # raster column c = axis-0 index; raster row r = n1 - 1 - axis-1 index (far at top)
        i0, i1 = np.meshgrid(np.arange(n0), np.arange(n1), indexing="ij")
        design = np.stack([i0 + 0.5, (n1 - 1 - i1) + 0.5, np.ones_like(i0)], axis=-1)
        a = design.reshape(-1, 3).astype(np.float64)
        lonlat = lla[..., [1, 0]].reshape(-1, 2)
        coef, *_ = np.linalg.lstsq(a, lonlat, rcond=None)
        transform = np.asarray(coef.T, dtype=np.float64)  # (2, 3)
        fit = a @ coef
        m_per_deg = np.array([np.cos(np.radians(geo.origin.lla[0])), 1.0]) * 111_320.0
        residual = float(np.max(np.linalg.norm((fit - lonlat) * m_per_deg, axis=1)))
        matrix = [*transform[0][:2], 0.0, transform[0][2], *transform[1][:2], 0.0]
        matrix += [transform[1][2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
        path = out_dir / f"image_geo_{k:02d}.tif"
        tifffile.imwrite(
            path,
            gray_db(seg.image.data, max_px=max(n0, n1)),
            photometric="minisblack",
            extratags=[
                (MODEL_TRANSFORMATION_TAG, "d", 16, matrix, True),
                (GEO_KEY_DIRECTORY_TAG, "H", 16, [v for key in _GEO_KEYS for v in key], True),
            ],
        )
        written.append(GeoTiff(path, transform, residual))
    return written
