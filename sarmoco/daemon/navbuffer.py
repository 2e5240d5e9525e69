"""Navigation buffer: seconds of INS history, late samples put in order, bad times refused.

Two streams are held apart because INS links send them in different messages at
different instants: kinematics (velocity, and position when the source gives
one) and attitude (quaternion). Each :class:`NavStream`

- keeps the samples sorted by GPS time; a late (reordered) sample is inserted
  in its place, a second sample at the same time is refused (``DUPLICATE``);
- keeps ``history_ns`` of history behind its newest sample and refuses older
  samples (``STALE``): stale data are dropped, never buffered forever;
- keeps, beyond that, the samples from a time it is told to hold
  (:meth:`NavStream.hold`: the oldest pulse the focuser has not reached yet), so a
  focuser that lags never finds the navigation of its pulses gone; ``capacity`` bounds
  the memory this takes (the oldest are then evicted and counted);
- checks every sample's GPS stamp against the host clock it was received on,
  when the caller gives that receive time: the latency ``rx - t`` of a healthy
  source varies by the link jitter only, so a sample whose latency departs from
  the recent median by more than ``clock_tolerance_ns`` carries a wrong stamp
  (an INS clock step, a mapping that has not caught up) and is refused
  (``CLOCK_REJECTED``). Refused samples leave a gap that the aligner flags;
  nothing is bridged. If the new latency persists for ``rebase_after_ns`` of
  receive time, it is taken as the new normal (a changed link): the history is
  cleared and samples at or before the newest one held before the change are
  refused, so navigation from both sides of the change is never mixed.

The receive clock only needs a constant rate (``time.monotonic_ns()``); its
offset to GPS is irrelevant. In replay there is no receive time and the check is
off.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from sarmoco.drivers.samples import AttitudeSample, VelocitySample
from sarmoco.errors import ProcessingError
from sarmoco.processing.types import FloatArray, IntArray, NavSamples
from sarmoco.store.flags import PushResult

NO_TIME = np.iinfo(np.int64).min
"""Marker for "no sample" in :meth:`NavStream.bracket` results."""

_LATENCY_MEDIAN_OF = 32

HOLD_EXTRA = 2
"""Samples kept before a held time (:meth:`NavStream.hold`): the aligner's attitude
window reaches two samples beyond the pulses it interpolates."""


class NavStream:
    """Time-sorted samples of one vector quantity with bounded history.

    Parameters
    ----------
    width : int
        Values per sample (e.g. 6 for velocity and position, 4 for a quaternion).
    history_ns : int
        History kept behind the newest sample, ns.
    capacity : int
        Most samples held; beyond it the oldest are evicted (counted in ``evicted``).
    clock_tolerance_ns : int
        Allowed departure of a sample's latency from the recent median, ns.
    rebase_after_ns : int
        Receive-time span over which a consistent new latency is accepted, ns. It
        must exceed the time the source's clock mapping takes to correct a step.
    """

    def __init__(
        self,
        width: int,
        history_ns: int,
        capacity: int,
        clock_tolerance_ns: int,
        rebase_after_ns: int,
    ) -> None:
        if width < 1 or history_ns <= 0 or capacity < 2 or clock_tolerance_ns <= 0:
            raise ProcessingError(
                f"NavStream: width {width}, history_ns {history_ns}, capacity {capacity}, "
                f"clock_tolerance_ns {clock_tolerance_ns} must be positive (capacity >= 2)"
            )
        self.history_ns = history_ns
        self.clock_tolerance_ns = clock_tolerance_ns
        self.rebase_after_ns = rebase_after_ns
        self._t = np.zeros(capacity, dtype=np.int64)
        self._v = np.zeros((capacity, width), dtype=np.float64)
        self._lo = 0
        self._hi = 0
        self._refuse_until_ns = NO_TIME  # samples at or before this time are refused
        self._hold_ns: int | None = None  # samples from here on are kept (hold)
        self._latency: deque[int] = deque(maxlen=_LATENCY_MEDIAN_OF)
        self._candidates: list[tuple[int, int]] = []  # (rx_ns, latency) of refused samples
        self._lock = threading.Lock()
        self.counts = {result.name.lower(): 0 for result in PushResult}
        self.counts.update(evicted=0, reordered=0, rebased=0)

    @property
    def t_ns(self) -> IntArray:
        """Times of the held samples, GPS ns, increasing (a view: do not keep it)."""
        return self._t[self._lo : self._hi]

    @property
    def values(self) -> FloatArray:
        """Values of the held samples, ``(N, width)`` (a view: do not keep it)."""
        return self._v[self._lo : self._hi]

    def __len__(self) -> int:
        return self._hi - self._lo

    def push(
        self, t_ns: int, values: Sequence[float] | FloatArray, rx_ns: int | None = None
    ) -> PushResult:
        """Offer one sample.

        Parameters
        ----------
        t_ns : int
            Sample time, GPS ns.
        values : sequence of float
            ``width`` values.
        rx_ns : int, optional
            Host receive time on any constant-rate clock, ns; enables the clock check.

        Returns
        -------
        PushResult
            Whether the sample was kept, and if not why.
        """
        with self._lock:
            result = self._classify(t_ns, rx_ns)
            self.counts[result.name.lower()] += 1
            if result is PushResult.ACCEPTED:
                self._insert(t_ns, values)
        return result

    def hold(self, t_ns: int | None) -> None:
        """Keep the samples at or after ``t_ns`` (GPS ns) and the :data:`HOLD_EXTRA`
        before it however old they grow (until ``capacity`` evicts them); None: keep
        ``history_ns`` only. Takes effect at the next sample."""
        with self._lock:
            self._hold_ns = t_ns

    def _classify(self, t_ns: int, rx_ns: int | None) -> PushResult:
        newest = self._t[self._hi - 1] if len(self) else NO_TIME
        if rx_ns is not None and not self._clock_consistent(t_ns, rx_ns, int(newest)):
            return PushResult.CLOCK_REJECTED
        if t_ns <= self._refuse_until_ns:
            return PushResult.CLOCK_REJECTED
        if len(self) and t_ns < newest - self.history_ns:
            return PushResult.STALE
        i = int(np.searchsorted(self.t_ns, t_ns))
        if i < len(self) and self.t_ns[i] == t_ns:
            return PushResult.DUPLICATE
        return PushResult.ACCEPTED

    def _clock_consistent(self, t_ns: int, rx_ns: int, newest: int) -> bool:
        """Latency check against the recent median; may rebase (see the module doc)."""
        latency = rx_ns - t_ns
        if not self._latency or abs(latency - np.median(self._latency)) <= self.clock_tolerance_ns:
            self._latency.append(latency)
            self._candidates.clear()
            return True
        if self._candidates and abs(latency - self._candidates[0][1]) > self.clock_tolerance_ns:
            self._candidates.clear()
        self._candidates.append((rx_ns, latency))
        if rx_ns - self._candidates[0][0] < self.rebase_after_ns:
            return False
        self._latency.clear()
        self._latency.extend(lat for _, lat in self._candidates[-_LATENCY_MEDIAN_OF:])
        self._candidates.clear()
        self._refuse_until_ns = max(self._refuse_until_ns, newest)
        self._lo = self._hi = 0
        self.counts["rebased"] += 1
        return True

    def _insert(self, t_ns: int, values: Sequence[float] | FloatArray) -> None:
        cap = self._t.shape[0]
        if self._hi == cap:
            if self._lo == 0:  # full of history: evict the oldest
                self._lo = 1
                self.counts["evicted"] += 1
            n = len(self)
            self._t[:n] = self._t[self._lo : self._hi]
            self._v[:n] = self._v[self._lo : self._hi]
            self._lo, self._hi = 0, n
        i = self._lo + int(np.searchsorted(self.t_ns, t_ns))
        if i < self._hi:  # late sample: shift the newer ones up by one
            self._t[i + 1 : self._hi + 1] = self._t[i : self._hi]
            self._v[i + 1 : self._hi + 1] = self._v[i : self._hi]
            self.counts["reordered"] += 1
        self._t[i] = t_ns
        self._v[i] = values
        self._hi += 1
        horizon = self._t[self._hi - 1] - self.history_ns
        drop = int(np.searchsorted(self.t_ns, horizon))
        if self._hold_ns is not None:
            held = int(np.searchsorted(self.t_ns, self._hold_ns)) - HOLD_EXTRA
            drop = min(drop, max(held, 0))
        self._lo += drop

    def span_ns(self) -> tuple[int, int] | None:
        """Times of the oldest and the newest held sample, GPS ns; None when empty."""
        with self._lock:
            if self._hi == self._lo:
                return None
            return int(self._t[self._lo]), int(self._t[self._hi - 1])

    def bracket(self, t_ns: IntArray) -> tuple[IntArray, IntArray]:
        """The held samples around each query time.

        Parameters
        ----------
        t_ns : ndarray of int64
            Query times, GPS ns.

        Returns
        -------
        before, after : ndarray of int64
            Time of the newest sample at or before, and of the oldest sample at or
            after, each query (:data:`NO_TIME` where there is none).
        """
        with self._lock:
            t = self.t_ns.copy()
        before = np.full(t_ns.shape, NO_TIME, dtype=np.int64)
        after = np.full(t_ns.shape, NO_TIME, dtype=np.int64)
        i_before = np.searchsorted(t, t_ns, side="right") - 1
        ok = i_before >= 0
        before[ok] = t[i_before[ok]]
        i_after = np.searchsorted(t, t_ns, side="left")
        ok = i_after < len(t)
        after[ok] = t[i_after[ok]]
        return before, after

    def window(self, t0_ns: int, t1_ns: int, extra: int = 1) -> tuple[IntArray, FloatArray]:
        """Copies of the samples in ``[t0_ns, t1_ns]`` and ``extra`` beyond each end, if held."""
        with self._lock:
            t = self.t_ns
            lo = max(int(np.searchsorted(t, t0_ns, side="left")) - extra, 0)
            hi = min(int(np.searchsorted(t, t1_ns, side="right")) + extra, len(t))
            return t[lo:hi].copy(), self.values[lo:hi].copy()


class NavBuffer:
    """Kinematics and attitude streams of one INS (see the module doc).

    Parameters
    ----------
    history_ns : int
        History kept, ns (several seconds: longer than the latency budget).
    capacity : int
        Samples held per stream at most (history x the highest INS rate, with margin).
    clock_tolerance_ns : int
        See :class:`NavStream`; larger than the link jitter plus reordering delay.
    rebase_after_ns : int
        See :class:`NavStream`; longer than the clock mapping's correction time.
    """

    def __init__(
        self,
        history_ns: int = 10_000_000_000,
        capacity: int = 8192,
        clock_tolerance_ns: int = 20_000_000,
        rebase_after_ns: int = 3_000_000_000,
    ) -> None:
        args = (history_ns, capacity, clock_tolerance_ns, rebase_after_ns)
        self.kinematics = NavStream(6, *args)
        """Velocity NED (m/s) then position NED (m, NaN when the source has none)."""
        self.attitude = NavStream(4, *args)
        """Quaternion, scalar first, body to NED."""

    def push_velocity(
        self,
        t_ns: int,
        vel_ned: Sequence[float],
        pos_ned: Sequence[float] | None = None,
        rx_ns: int | None = None,
    ) -> PushResult:
        """Offer one velocity (m/s) and position (m) sample at GPS ``t_ns`` ns."""
        pos = (np.nan, np.nan, np.nan) if pos_ned is None else tuple(pos_ned)
        return self.kinematics.push(t_ns, (*vel_ned, *pos), rx_ns)

    def push_attitude(
        self, t_ns: int, quat: Sequence[float], rx_ns: int | None = None
    ) -> PushResult:
        """Offer one attitude sample (scalar-first quaternion, body to NED)."""
        return self.attitude.push(t_ns, quat, rx_ns)

    def push_sample(
        self, sample: VelocitySample | AttitudeSample, rx_ns: int | None = None
    ) -> PushResult:
        """Offer one driver sample (velocity or attitude)."""
        if isinstance(sample, VelocitySample):
            return self.push_velocity(sample.t_gps_ns, sample.vel_ned, sample.pos_ned, rx_ns)
        return self.push_attitude(sample.t_gps_ns, sample.quat, rx_ns)

    def push_nav(self, nav: NavSamples, rx_ns: IntArray | None = None) -> npt.NDArray[np.int8]:
        """Offer joint samples (simulator, recorded runs); returns one :class:`PushResult` each."""
        out = np.empty(nav.t_ns.shape[0], dtype=np.int8)
        for k, t in enumerate(nav.t_ns.tolist()):
            rx = None if rx_ns is None else int(rx_ns[k])
            pos = None if nav.pos_ned is None else nav.pos_ned[k]
            r_kin = self.push_velocity(t, nav.vel_ned[k], pos, rx)
            r_att = self.push_attitude(t, nav.quat[k], rx)
            out[k] = max(r_kin, r_att)
        return out

    def hold(self, t_ns: int | None) -> None:
        """Keep both streams' samples from ``t_ns`` on (GPS ns; None: history only), see
        :meth:`NavStream.hold`."""
        self.kinematics.hold(t_ns)
        self.attitude.hold(t_ns)

    def span_ns(self) -> tuple[int, int] | None:
        """Times that both streams hold samples over, GPS ns: from the later of their
        oldest samples to the earlier of their newest; None while either is empty."""
        spans = (self.kinematics.span_ns(), self.attitude.span_ns())
        if spans[0] is None or spans[1] is None:
            return None
        return max(spans[0][0], spans[1][0]), min(spans[0][1], spans[1][1])

    def counts(self) -> dict[str, int]:
        """Counters of both streams, keys ``kinematics_<name>`` and ``attitude_<name>``."""
        return {
            f"{name}_{key}": value
            for name, stream in (("kinematics", self.kinematics), ("attitude", self.attitude))
            for key, value in stream.counts.items()
        }
