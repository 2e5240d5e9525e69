"""Block assembly and focusing: aligned pulses into processing blocks, through the focuser.

The aligner releases pulses with their navigation as the INS allows, in blocks of any
size; :class:`BlockFocusing` gathers them and hands the focuser
(:class:`~sarmoco.daemon.focuser.Focuser`) ``imaging.block_pulses`` at a time, so that a
live run and a replay of its store cut the stream alike (the autofocus estimates depend
on the cuts at the level of rounding). On the way:

- pulses not later than every pulse focused before are kept from the focuser (it needs
  strictly increasing times), counted in ``pulses_out_of_order``;
- the focuser starts at the first pulse with navigation, on a reference track along the
  mean antenna velocity of the pulses of ``mocomp.heading_window_s`` of flight from there
  when the pulses are held for it (a replay: ``hold_course``), else of the first
  processing block's (a live run: no pulse waits for the course); the pulses before it
  are recorded unfocused;
- pulses without navigation keep their place with zero echoes
  (:class:`~sarmoco.daemon.navigation.GapFill`);
- a pulse whose store row does not follow the row of the pulse focused before it comes
  after pulses that focusing skipped (the focus backlog's skip ahead): the focuser is told
  (``after_skip``), and carries its segment across the hole instead of starting a new one.

Every pulse ends in the motion table (:class:`~sarmoco.daemon.tables.RunTables`), with a
solution or without, and is counted processed, unfocused or out of order.
"""

from __future__ import annotations

import logging

import numpy as np

from sarmoco.daemon.aligner import AlignedBlock
from sarmoco.daemon.config import Config
from sarmoco.daemon.focuser import Focuser, SinkFactory
from sarmoco.daemon.navigation import GapFill, NavPulses
from sarmoco.daemon.tables import RunTables
from sarmoco.processing.types import BoolArray, IntArray
from sarmoco.store.flags import NAV_UNUSABLE

log = logging.getLogger(__name__)


class BlockFocusing:
    """Aligned pulses gathered into processing blocks and focused (see the module doc).

    Parameters
    ----------
    cfg : Config
        Daemon configuration (``imaging.block_pulses``, ``mocomp.heading_window_s``, and
        the focuser's own).
    tables : RunTables
        Where the pulses' motion and the products are recorded and counted.
    sink : SinkFactory, optional
        Imaging deferred (:class:`~sarmoco.daemon.focuser.Focuser`).
    hold_course : bool
        Hold the first pulses until they cover ``mocomp.heading_window_s`` (or the run
        ends), and lay the first reference track along their mean velocity (a replay,
        where the pulses wait for nothing); otherwise along the first processing block's.
    """

    def __init__(
        self,
        cfg: Config,
        tables: RunTables,
        sink: SinkFactory | None = None,
        hold_course: bool = False,
    ) -> None:
        self.cfg = cfg
        self.tables = tables
        self.sink = sink
        self._window_ns = course_window_ns(cfg) if hold_course else 0
        """Flight the first reference track's course is taken over, GPS ns (0: one block)."""
        self.focuser: Focuser | None = None
        """The focusing chain, from the first pulse with navigation on (None before)."""
        self._gaps: GapFill | None = None
        self._pending: list[NavPulses] = []
        """Aligned pulses not focused yet, oldest first."""
        self._pending_n = 0
        self._focused_ns: int | None = None
        """Time of the newest pulse given to the focuser, GPS ns."""
        self._last_row: int | None = None
        """Store row of the newest pulse given to the focuser."""

    def accept(self, block: AlignedBlock) -> None:
        """Take an aligned block: record its navigation flags, and focus every whole
        processing block gathered (once the first track's course is held)."""
        self.tables.nav_flags(block)
        self._pending.append(NavPulses.of(block))
        self._pending_n += len(block)
        if self.focuser is None and not self._course_held():
            return  # the first track waits for its course
        block_pulses = self.cfg.imaging.block_pulses
        while self._pending_n >= block_pulses:
            self._focus_pending(block_pulses)

    def finish(self) -> None:
        """Focus every pulse still gathered (a block at a time) and close the focuser."""
        while self._pending_n > 0:  # a block at a time: held for the course, or the last
            self._focus_pending(min(self._pending_n, self.cfg.imaging.block_pulses))
        if self.focuser is not None:
            self.tables.products(self.focuser.finish(), self.focuser.autofocus)

    def _focus_pending(self, n: int) -> None:
        """Focus the first ``n`` pulses gathered, and record their motion and products."""
        if not self._pending:
            return
        pending = NavPulses.cat(self._pending)
        self._pending = [pending.since(n)] if n < len(pending) else []
        self._pending_n = len(pending) - n
        in_order = self._in_time_order(pending.upto(n))
        if in_order is None:
            return
        summary = self.tables.summary
        summary.pulses_nav_flagged += int(np.count_nonzero(in_order.flags & NAV_UNUSABLE))
        p = in_order if self.focuser is not None else self._start(in_order, pending)
        if p is None:
            return  # no navigation yet: the aperture has not begun
        assert self.focuser is not None and self._gaps is not None
        p = self._gaps.fill(p)
        out = self.focuser.push(p.raw, p.t_ns, p.vel_ned, p.usable, p.quat, self._after_skip(p))
        self.tables.motion(p, out)
        self.tables.products(out, self.focuser.autofocus)

    def _after_skip(self, p: NavPulses) -> BoolArray:
        """The pulses of ``p`` (about to be focused) whose store row is more than one past
        the row focused before them: recorded pulses between them were skipped."""
        before = p.row[0] - 1 if self._last_row is None else self._last_row
        self._last_row = int(p.row[-1])
        return np.asarray(np.diff(p.row, prepend=before) > 1, dtype=bool)

    def _in_time_order(self, p: NavPulses) -> NavPulses | None:
        """``p`` without the pulses not after every pulse focused before (counted in
        :attr:`~sarmoco.daemon.tables.RunSummary.pulses_out_of_order`: the focuser needs
        strictly increasing times); None if none is left."""
        fresh = strictly_increasing(p.t_ns, self._focused_ns)
        if not fresh.all():
            self.tables.summary.pulses_out_of_order += int(np.count_nonzero(~fresh))
            log.warning("pulses out of time order kept from the focuser",
                        extra={"pulses": int(np.count_nonzero(~fresh))})  # fmt: skip
            p = p.rows(fresh)
            if len(p) == 0:
                return None
        self._focused_ns = int(p.t_ns[-1])
        return p

    def _course_held(self) -> bool:
        """Whether the pulses gathered and not focused cover the course's window from the
        first one with navigation (or none has navigation, or no window: nothing to wait
        for)."""
        first = next((int(p.t_ns[p.usable][0]) for p in self._pending if p.usable.any()), None)
        if first is None or self._window_ns == 0:
            return True
        return int(self._pending[-1].t_ns[-1]) >= first + self._window_ns

    def _start(self, p: NavPulses, held: NavPulses) -> NavPulses | None:
        """Start the focuser at the first pulse of ``p`` with navigation; the pulses from
        there on (the pulses before it are recorded unfocused).

        The first reference track follows the mean velocity of the usable pulses ``held``
        (``p`` and the pulses gathered after it) within the course's window of that first
        one, or (no window) of the first ``imaging.block_pulses`` usable pulses of ``p``.
        None while no pulse has navigation.
        """
        if not p.usable.any():
            self.tables.unfocused(p)
            return None
        first_usable = int(np.argmax(p.usable))
        self.tables.unfocused(p.upto(first_usable))
        p = p.since(first_usable)
        t0 = int(p.t_ns[0])
        first = slice(0, self.cfg.imaging.block_pulses)
        if self._window_ns == 0:
            start_vel = p.vel_ned[p.usable][first].mean(axis=0)
        else:
            window = held.usable & (held.t_ns >= t0) & (held.t_ns < t0 + self._window_ns)
            start_vel = held.vel_ned[window].mean(axis=0)
        self.focuser = Focuser(self.cfg, t0, start_vel, self.sink, quat=p.quat[p.usable][first])
        self._gaps = GapFill(t0, p.vel_ned[0], p.quat[0])
        # a store that refuses the track (RecorderError) leaves the state whole for the next
        # block; zarr keeps the attribute and writes it with the root's next attributes
        self.tables.reference_track(self.focuser.track)
        return p


HOLD_MAX_BYTES = 512 * 2**20
"""Most echo bytes held for the first reference track's course (complex64 samples): at
high pulse rates the window is shortened to what this holds (thz-spotlight: 0.8 s)."""


def course_window_ns(cfg: Config) -> int:
    """``mocomp.heading_window_s`` in ns, shortened to the pulses :data:`HOLD_MAX_BYTES`
    holds at the nominal PRF."""
    pulse_bytes = cfg.radar.n_samples * cfg.radar.channels * np.dtype(np.complex64).itemsize
    held_s = HOLD_MAX_BYTES / (pulse_bytes * cfg.radar.prf_hz)
    return round(min(cfg.mocomp.heading_window_s, held_s) * 1e9)


def strictly_increasing(t_ns: IntArray, after_ns: int | None) -> BoolArray:
    """Mask of the pulses later than ``after_ns`` (GPS ns) and than every pulse before them."""
    floor = np.iinfo(np.int64).min if after_ns is None else after_ns
    before = np.maximum.accumulate(np.concatenate([[floor], t_ns[:-1]]))
    return np.asarray(t_ns > before, dtype=bool)
