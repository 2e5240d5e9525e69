"""What the live page and the camera component show, handed over in memory by the
recorder as it records.

The recorder (in the processing thread) publishes each tile it records and each batch
of autofocus estimates to a :class:`LiveFeed`; the status server's HTTP threads take a
consistent :class:`LiveSnapshot` of it under one lock, and the MAVLink camera component
the time span of every tile stored (:meth:`LiveFeed.stored_tiles`). Nothing here opens the store: a
live run's page never reads the store the run is writing (no zarr metadata read per
request, no race with a half-written tile).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sarmoco.processing.types import ComplexArray, Image

LIVE_TILES = 4
"""Newest tiles the live page's strip shows (and the feed keeps)."""

LIVE_AUTOFOCUS_ROWS = 300
"""Newest autofocus estimates the live page plots (and the feed keeps)."""

AUTOFOCUS_KEYS = {"t_center_s": "t_s", "a_y_mps2": "a_y_mps2", "a_z_mps2": "a_z_mps2"}
"""Columns of the store's ``autofocus`` table the page plots, to their ``/live.json`` names:
subaperture centre time (s on the autofocus time axis), cross-track accelerations (m/s²)."""


@dataclass(frozen=True)
class LiveTile:
    """One recorded tile as the live page draws it.

    Attributes
    ----------
    index : int
        The tile's index in the store.
    x0_m : float
        Along-track (imaging-frame x) position of its first row, m.
    data : ndarray of complex, shape (n_az, n_rg)
        Its complex pixels: the recorded tile's array itself (not copied; a recorded
        tile is never changed).
    """

    index: int
    x0_m: float
    data: ComplexArray


@dataclass(frozen=True)
class LiveSnapshot:
    """The feed at one instant.

    Attributes
    ----------
    n_tiles : int
        Tiles recorded so far.
    tiles : tuple of LiveTile
        The newest :data:`LIVE_TILES` of them, oldest first.
    autofocus : dict of str to list of float
        The newest :data:`LIVE_AUTOFOCUS_ROWS` estimates, by ``/live.json`` name
        (:data:`AUTOFOCUS_KEYS`), oldest first.
    """

    n_tiles: int
    tiles: tuple[LiveTile, ...]
    autofocus: dict[str, list[float]]


class LiveFeed:
    """Thread-safe, bounded record of the newest tiles and autofocus estimates of a run, and
    the time span of each tile recorded."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._n_tiles = 0
        self._spans: list[tuple[int, int, int]] = []
        self._tiles: deque[LiveTile] = deque(maxlen=LIVE_TILES)
        self._autofocus: dict[str, deque[float]] = {
            k: deque(maxlen=LIVE_AUTOFOCUS_ROWS) for k in AUTOFOCUS_KEYS
        }

    def add_tile(self, index: int, image: Image, t0_ns: int, t1_ns: int) -> None:
        """A tile was recorded at store index ``index``, formed of the pulses from ``t0_ns``
        to ``t1_ns`` (GPS ns)."""
        tile = LiveTile(index, float(image.axis0_m[0]), image.data)
        with self._lock:
            self._tiles.append(tile)
            self._n_tiles = max(self._n_tiles, index + 1)
            self._spans.append((index, t0_ns, t1_ns))

    def stored_tiles(self, start: int = 0) -> list[tuple[int, int, int]]:
        """Store index and pulse span (GPS ns) of every tile recorded, from the
        ``start``-th, in the order they were recorded."""
        with self._lock:
            return self._spans[start:]

    def add_autofocus(self, columns: Mapping[str, npt.ArrayLike]) -> None:
        """Rows of the ``autofocus`` table were recorded (every column of
        :data:`AUTOFOCUS_KEYS` must be there; the others are not kept)."""
        values = {k: np.asarray(columns[k], dtype=np.float64).tolist() for k in AUTOFOCUS_KEYS}
        with self._lock:
            for k, v in values.items():
                self._autofocus[k].extend(v)

    def snapshot(self) -> LiveSnapshot:
        """The tile count, newest tiles and newest autofocus estimates, all of one instant."""
        with self._lock:
            return LiveSnapshot(
                self._n_tiles,
                tuple(self._tiles),
                {AUTOFOCUS_KEYS[k]: list(v) for k, v in self._autofocus.items()},
            )
