"""The rule by which the live image degrades when focusing cannot keep up.

The live imager (``imaging.method = "rda"`` or ``"pfa"``) forms tiles at a level of
:data:`~sarmoco.processing.imaging.rda_tiles.LEVELS` (0: the configured pixel spacing,
swath and Doppler band; 1 doubles the pixel spacing and presums by 2 (half the Doppler
band: azimuth resolution twice as coarse), 2 also halves the swath, 3 doubles the pixel
spacing and the presum again). Data are never dropped: every pulse is recorded, and a
replay of the store forms the full image.

Below level 0 is one more rung, *prompt* tiles: the range-Doppler imager forms every tile
alone as soon as the pulses reach a half footprint past it, instead of in blocks of
tiles that together reach a half footprint (ku-vehicle: four, whose first tile then waits
three tile lengths of flight, 1.7 s, past its last pulse). Prompt tiles are the same image
as level 0's, sooner, at :data:`PROMPT_COST` times level 0's focusing cost: the rule
trades the tiles' latency before their resolution. The ladder of rungs is prompt, then
levels 0 to 3 in blocks; the polar format imager forms each tile alone at every rung.

The rule, on the load ``L``: wall seconds the focuser spent per second of data, an
exponential average over ``imaging.live_window_s`` of data, and the focusing cost of each
rung relative to level 0, :data:`PROMPT_COST` and :data:`LEVEL_COST` (measured, not
modelled: the levels make the tiles cheaper, not the stages before them):

- **up** one rung when ``L > B`` (``imaging.live_budget``);
- **down** one rung when ``L c_(r-1) / c_r < HEADROOM B`` (the rung below, at its
  measured cost, would still leave a margin);
- after a change, no other change until another window of data has been focused (the
  average then reflects the new rung).

The rule starts at level ``imaging.live_min_level`` in blocks and reaches prompt tiles (at
level 0) only by stepping down, when their cost fits with the headroom: a focuser that
cannot keep up climbs the levels from level 0 in blocks (started at the costlier prompt
rung, one on a loaded machine fell further behind, skipping more pulses, while the rule
held it a window at each rung). The level, whether tiles are
prompt and the load are served as the status gauges ``live_image_level``,
``live_image_prompt`` and ``live_image_load``; the live page shows the level in words
(:func:`level_names`).
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

PROMPT_COST = 1.3
"""Focusing CPU per second of data with prompt tiles at level 0, over level 0's in blocks:
the same chain as :data:`LEVEL_COST`, ``python -m bench.bench_live_focuser --pulses 12000
[--prompt]``, the steady part's cost taken as the tile imager's CPU per tile times the tiles
per data second plus the rest of the chain (a steady part holds a whole number of blocks of
tiles, not of tiles); median of four pairs (1.17-1.66 on a loaded machine)."""

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
        Lowest level (``imaging.live_min_level``): the rule starts there in blocks and never
        goes below it (0: prompt tiles are its lowest rung).
    """

    def __init__(self, budget: float, window_s: float, floor: int = 0) -> None:
        if not (budget > 0 and window_s > 0):
            raise ConfigError(f"LiveLevel: budget {budget!r}, window {window_s!r} s not > 0")
        if not 0 <= floor < len(LEVELS):
            raise ConfigError(f"LiveLevel: lowest level {floor!r} not in 0..{len(LEVELS) - 1}")
        self.budget = float(budget)
        self.window_s = float(window_s)
        self.floor = floor
        self._costs = (PROMPT_COST, *LEVEL_COST)
        """Cost of each rung: prompt tiles, then levels 0 .. 3 in blocks."""
        self._lowest = floor + 1 if floor else 0
        self.rung = floor + 1
        """Current rung: 0 prompt tiles at level 0, ``l + 1`` level ``l`` in blocks."""
        self.load = 0.0
        """Focusing wall seconds per data second, averaged."""
        self._seen_s = 0.0
        """Data seconds since the last change (or the start)."""

    @property
    def level(self) -> int:
        """Current level of :data:`LEVELS`, ``floor`` .. len(LEVELS) - 1."""
        return max(self.rung - 1, 0)

    @property
    def prompt(self) -> bool:
        """Whether tiles are formed alone as soon as their pulses are in (the lowest rung)."""
        return self.rung == 0

    def update(self, data_s: float, busy_s: float) -> int:
        """Account ``busy_s`` wall seconds spent focusing ``data_s`` seconds of data; the
        level to form the next tiles at (and :attr:`prompt`, whether alone)."""
        if data_s <= 0.0:
            return self.level
        weight = min(1.0, data_s / self.window_s)
        self.load += weight * (busy_s / data_s - self.load)
        self._seen_s += data_s
        if self._seen_s < self.window_s:
            return self.level
        if self.load > self.budget and self.rung < len(self._costs) - 1:
            self._change(+1)
        elif self.rung > self._lowest and self._at(self.rung - 1) < HEADROOM * self.budget:
            self._change(-1)
        return self.level

    def _at(self, rung: int) -> float:
        """The load expected at ``rung`` from the load at the current one (:data:`PROMPT_COST`,
        :data:`LEVEL_COST`)."""
        return self.load * self._costs[rung] / self._costs[self.rung]

    def _change(self, step: int) -> None:
        self.load = self._at(self.rung + step)
        self.rung += step
        self._seen_s = 0.0
