"""The rule by which the live image degrades when focusing cannot keep up.

The live imager (``imaging.method = "rda"`` or ``"pfa"``) forms tiles at a level of
:data:`~sarmoco.processing.imaging.rda_tiles.LEVELS` (0: the configured pixel spacing,
swath and Doppler band; 1 doubles the pixel spacing and presums by 2 (half the Doppler
band: azimuth resolution twice as coarse), 2 also halves the swath, 3 doubles the pixel
spacing and the presum again). Data are never dropped: every pulse is recorded, and a
replay of the store forms the full image.

The rule, on the load ``L``: wall seconds the focuser spent per second of data, an
exponential average over ``imaging.live_window_s`` of data, and the focusing cost of each
level relative to level 0, :data:`LEVEL_COST` (measured, not modelled: the levels make
the tiles cheaper, not the stages before them):

- **up** one level when ``L > B`` (``imaging.live_budget``);
- **down** one level when ``L c_(l-1) / c_l < HEADROOM B`` (the level below, at its
  measured cost, would still leave a margin);
- after a change, no other change until another window of data has been focused (the
  average then reflects the new level).

The level and the load are served as the status gauges ``live_image_level`` and
``live_image_load``; the live page shows the level in words (:func:`level_names`).
"""

from __future__ import annotations

from sarmoco.errors import ConfigError
from sarmoco.processing.imaging.rda_tiles import LEVELS

LEVEL_COST = (1.0, 0.86, 0.85, 0.84)
"""Focusing CPU per second of data at each level of
:data:`~sarmoco.processing.imaging.rda_tiles.LEVELS`, over level 0's: the live chain of a
full-size ku-vehicle (pre-filter first, autofocus on, range-Doppler tiles) with the level
held, ``python -m bench.bench_live_focuser --level N`` (steady part, median of three runs;
the figures in ``docs/measurements/live-imager.md``)."""

HEADROOM = 0.7
"""Share of the budget the level below must fit in before the rule steps down."""


def level_names() -> list[str]:
    """Each level of :data:`LEVELS` in words, for the operator (level 0: ``"full"``)."""
    names = []
    for pixel, narrow, presum in LEVELS:
        parts = (
            ([f"pixels x{pixel}"] if pixel > 1 else [])
            + ([f"swath 1/{narrow}"] if narrow > 1 else [])
            + ([f"presum x{presum}"] if presum > 1 else [])
        )
        names.append(", ".join(parts) or "full")
    return names


class LiveLevel:
    """The degraded level of the live image, from the focuser's load (see the module).

    Parameters
    ----------
    budget : float
        Focusing wall seconds per data second above which the level goes up (``B``).
    window_s : float
        Data seconds of the load's exponential average, and of the hold after a change, s.
    floor : int
        Lowest level (``imaging.live_min_level``): the rule starts there and never goes
        below it.
    """

    def __init__(self, budget: float, window_s: float, floor: int = 0) -> None:
        if not (budget > 0 and window_s > 0):
            raise ConfigError(f"LiveLevel: budget {budget!r}, window {window_s!r} s not > 0")
        if not 0 <= floor < len(LEVELS):
            raise ConfigError(f"LiveLevel: lowest level {floor!r} not in 0..{len(LEVELS) - 1}")
        self.budget = float(budget)
        self.window_s = float(window_s)
        self.floor = floor
        self.level = floor
        """Current level, ``floor`` .. len(LEVELS) - 1."""
        self.load = 0.0
        """Focusing wall seconds per data second, averaged."""
        self._seen_s = 0.0
        """Data seconds since the last change (or the start)."""

    def update(self, data_s: float, busy_s: float) -> int:
        """Account ``busy_s`` wall seconds spent focusing ``data_s`` seconds of data; the
        level to form the next tiles at."""
        if data_s <= 0.0:
            return self.level
        weight = min(1.0, data_s / self.window_s)
        self.load += weight * (busy_s / data_s - self.load)
        self._seen_s += data_s
        if self._seen_s < self.window_s:
            return self.level
        if self.load > self.budget and self.level < len(LEVELS) - 1:
            self._change(+1)
        elif self.level > self.floor and self._at(self.level - 1) < HEADROOM * self.budget:
            self._change(-1)
        return self.level

    def _at(self, level: int) -> float:
        """The load expected at ``level`` from the load at the current one (:data:`LEVEL_COST`)."""
        return self.load * LEVEL_COST[level] / LEVEL_COST[self.level]

    def _change(self, step: int) -> None:
        self.load = self._at(self.level + step)
        self.level += step
        self._seen_s = 0.0
