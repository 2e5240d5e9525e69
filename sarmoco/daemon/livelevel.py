"""The rule by which the live image degrades when focusing cannot keep up.

The live imager (``imaging.method = "rda"`` or ``"pfa"``) forms tiles at a level of
:data:`~sarmoco.processing.imaging.rda_tiles.LEVELS` (0: the configured pixel spacing
and swath; each level about halves the cost of a tile: 1 doubles the pixel spacing,
2 also halves the swath, 3 doubles the pixel spacing again). Data are never dropped:
every pulse is recorded, and a replay of the store forms the full image.

The rule, on the load ``L``: wall seconds the focuser spent per second of data, an
exponential average over ``imaging.live_window_s`` of data:

- **up** one level when ``L > B`` (``imaging.live_budget``);
- **down** one level when ``2 L < HEADROOM B`` (the level below, at twice the cost,
  would still leave a margin);
- after a change, no other change until another window of data has been focused (the
  average then reflects the new level).

The level and the load are served as the status gauges ``live_image_level`` and
``live_image_load``; the live page shows the level in words (:func:`level_names`).
"""

from __future__ import annotations

from sarmoco.errors import ConfigError
from sarmoco.processing.imaging.rda_tiles import LEVELS

COST_STEP = 2.0
"""Cost of a tile at one level over its cost one level up (the rule's model)."""

HEADROOM = 0.7
"""Share of the budget the level below must fit in before the rule steps down."""


def level_names() -> list[str]:
    """Each level of :data:`LEVELS` in words, for the operator (level 0: ``"full"``)."""
    names = []
    for pixel, narrow in LEVELS:
        parts = ([f"pixels x{pixel}"] if pixel > 1 else []) + (
            [f"swath 1/{narrow}"] if narrow > 1 else []
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
    """

    def __init__(self, budget: float, window_s: float) -> None:
        if not (budget > 0 and window_s > 0):
            raise ConfigError(f"LiveLevel: budget {budget!r}, window {window_s!r} s not > 0")
        self.budget = float(budget)
        self.window_s = float(window_s)
        self.level = 0
        """Current level, 0 .. len(LEVELS) - 1."""
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
        elif COST_STEP * self.load < HEADROOM * self.budget and self.level > 0:
            self._change(-1)
        return self.level

    def _change(self, step: int) -> None:
        self.level += step
        self.load *= COST_STEP ** (-step)  # what the model expects at the new level
        self._seen_s = 0.0
