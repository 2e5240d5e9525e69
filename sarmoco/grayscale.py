"""8-bit gray pictures of a complex SAR image, without plotting: block-peak decimation,
a dB scale :data:`DYNAMIC_RANGE_DB` deep, PNG encoding. A few ms a tile, so the live page
draws its tile strip in the air with them; the GeoTIFF and the quicklooks on the ground use
the same scale.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import numpy.typing as npt

DYNAMIC_RANGE_DB = 40.0
"""Intensity range shown below the image peak, dB."""


def intensity_db(data: npt.NDArray[np.generic], reference: float) -> npt.NDArray[np.float64]:
    """Intensity of ``data`` in dB re the power ``reference``, floored at -DYNAMIC_RANGE_DB."""
    power = np.abs(np.asarray(data)) ** 2 / reference
    return np.asarray(10.0 * np.log10(np.maximum(power, 10 ** (-DYNAMIC_RANGE_DB / 10))))


def peak_blocks(data: npt.NDArray[np.generic], max_px: int = 600) -> npt.NDArray[np.float32]:
    """An image's magnitude laid out as a picture and decimated to at most ``max_px`` a side.

    Axis 0 of ``data`` (along track) becomes the horizontal axis of the picture and axis 1
    (ground range) the vertical one, far range at the top. Each axis is decimated to the
    peak of each block of pixels.
    """
    mag = np.abs(np.asarray(data)).T[::-1]
    k0, k1 = (max(1, -(-n // max_px)) for n in mag.shape)
    n0, n1 = mag.shape[0] // k0 * k0, mag.shape[1] // k1 * k1
    return np.asarray(
        mag[:n0, :n1].reshape(n0 // k0, k0, n1 // k1, k1).max(axis=(1, 3)), dtype=np.float32
    )


def gray_of(mag: npt.NDArray[np.floating], peak: float) -> npt.NDArray[np.uint8]:
    """Magnitudes as 8-bit gray: ``peak`` to 255, ``DYNAMIC_RANGE_DB`` below it and less to 0."""
    db = intensity_db(mag, peak**2 if peak > 0 else 1.0)
    return np.asarray(np.round((db / DYNAMIC_RANGE_DB + 1.0) * 255.0), dtype=np.uint8)


def gray_db(data: npt.NDArray[np.generic], max_px: int = 600) -> npt.NDArray[np.uint8]:
    """An image's intensity as 8-bit gray, ``DYNAMIC_RANGE_DB`` below its peak to 255
    (:func:`peak_blocks` laid out and decimated, :func:`gray_of` its own peak)."""
    mag = peak_blocks(data, max_px)
    return gray_of(mag, float(mag.max()) if mag.size else 0.0)


def png_gray(pixels: npt.NDArray[np.uint8]) -> bytes:
    """Encode 8-bit gray pixels (rows top to bottom) as a PNG file (no dependency)."""
    height, width = pixels.shape

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    rows = np.zeros((height, width + 1), dtype=np.uint8)  # filter byte 0 (none) per row
    rows[:, 1:] = pixels
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6))
        + chunk(b"IEND", b"")
    )
