"""Clock models that map a device's own clock onto GPS time.

* :class:`LinearClockFit` — offset and skew from (device time, reference time)
  pairs over a sliding window, with outlier rejection; used for SBG UTC_TIME,
  MAVLink SYSTEM_TIME and dataflash GPS records.
* :class:`TimesyncEstimator` — the MAVLink TIMESYNC exchange: minimum-round-trip
  filtering (only exchanges within a margin of the fastest recent round trip are
  trusted), offset and skew, reset on reboot, and a stated error bound.
* :class:`CounterUnwrapper` — extends a wrapping device counter and detects reboots.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from sarmoco.errors import ClockError

MAX_SKEW = 2e-4
"""Largest rate difference a clock fit believes, dimensionless (200 ppm). The crystal
oscillators of autopilots and INS are within about ±50 ppm; a larger fitted skew is the
noise of a few jittered pairs over a short window (a host under load delaying TIMESYNC
replies gave 2300 ppm over 1.5 s: 3.4 ms of error per 1.5 s in every INS time stamp)."""
EXTRAPOLATION_NS = 1_000_000_000
"""How far past its newest pair a clock fit is taken to be used, ns (exchanges come
several times a second)."""


class CounterUnwrapper:
    """Extends an ``bits``-wide wrapping counter to an unbounded one.

    Parameters
    ----------
    bits : int
        Counter width (32 for SBG microseconds).
    reboot_backstep : int
        A step backwards larger than this (counter units) that is not a wrap is
        a reboot: :meth:`unwrap` returns it with ``reset=True``.
    """

    def __init__(self, bits: int, reboot_backstep: int) -> None:
        self._mod = 1 << bits
        self._backstep = reboot_backstep
        self._wraps = 0
        self._last: int | None = None

    def unwrap(self, raw: int) -> tuple[int, bool]:
        """Extended value of ``raw`` and whether the device rebooted before it."""
        reset = False
        if self._last is not None:
            step = raw - self._last
            if step < -self._mod // 2:
                self._wraps += 1
            elif -self._mod // 2 <= step < -self._backstep:
                self._wraps = 0
                reset = True
            elif step > self._mod // 2 and self._wraps:
                return self._wraps * self._mod - self._mod + raw, False  # late pre-wrap value
        self._last = raw
        return self._wraps * self._mod + raw, reset


class LinearClockFit:
    """``reference = offset + (1 + skew) · device`` from a sliding window of pairs.

    Parameters
    ----------
    window : int
        Pairs kept.
    outlier_ns : int
        A pair further than this from the current fit is rejected (counted in
        :attr:`rejected`) once the fit has ``min_pairs`` pairs; a run of
        ``window // 2`` consecutive rejections means the reference stepped and
        the fit restarts from the new pairs.
    min_pairs : int
        Pairs needed before the skew is estimated (offset only before that).
    ready_pairs : int
        Pairs needed before :meth:`map` answers (:attr:`ready`); ``min_pairs``
        or more makes every answer use the skew, at the cost of waiting for
        that many pairs after start and after each reset.
    max_skew : float
        A fitted skew beyond ±``max_skew`` is clipped to it and the offset refitted with
        the clipped skew (see :data:`MAX_SKEW`).
    min_span_ns : int
        The skew is fitted only once the pairs span this much device time, ns
        (offset only before that). Pairs with noise σ over a span T give a skew
        noise of about σ √12 / (T √n): 0.1 ms over 0.6 s is 300 ppm, more than any
        crystal, while ignoring a 50 ppm skew over 2 s costs at most 0.1 ms.
    """

    def __init__(
        self,
        window: int = 16,
        outlier_ns: int = 2_000_000,
        min_pairs: int = 3,
        ready_pairs: int = 1,
        max_skew: float = MAX_SKEW,
        min_span_ns: int = 0,
    ) -> None:
        self._max_skew = max_skew
        self._min_span_ns = min_span_ns
        self._dev: deque[int] = deque(maxlen=window)
        self._ref: deque[int] = deque(maxlen=window)
        self._outlier_ns = outlier_ns
        self._min_pairs = min_pairs
        self._ready_pairs = ready_pairs
        self._run: list[tuple[int, int]] = []
        self._coef: tuple[int, int, float] | None = None
        self.rejected = 0
        self.residual_ns = 0.0
        """RMS residual of the current fit, ns."""
        self.unfitted_skew_ns = 0
        """While the fit is an offset only (too few pairs, or too short a span), the error
        a skew of :data:`MAX_SKEW` may cause over the pairs' span and
        :data:`EXTRAPOLATION_NS` beyond, ns (0 once the skew is fitted)."""
        self.leverage = 1.0
        """Sum of the magnitudes of the pairs' weights in the fitted value at the newest
        pair (1 for an offset; up to about 1.7 for a line through evenly spaced pairs): a
        bound on each pair's error, times this, bounds the error of the fit there."""

    @property
    def ready(self) -> bool:
        """Whether the fit holds ``ready_pairs`` pairs, so :meth:`map` answers."""
        return self._coef is not None and len(self._dev) >= self._ready_pairs

    def reset(self) -> None:
        """Forget every pair (device reboot, reference step)."""
        self._dev.clear()
        self._ref.clear()
        self._run.clear()
        self._coef = None

    def add(self, device_ns: int, reference_ns: int) -> bool:
        """Add one pair; returns False when it is rejected as an outlier."""
        if self._coef is not None and len(self._dev) >= self._min_pairs:
            if abs(self._map(device_ns) - reference_ns) > self._outlier_ns:
                self.rejected += 1
                self._run.append((device_ns, reference_ns))
                if len(self._run) >= max(2, (self._dev.maxlen or 2) // 2):
                    run = list(self._run)  # reset() clears self._run
                    self.reset()
                    for d, r in run:
                        self._append(d, r)
                    self._refit()
                return False
        self._run.clear()
        self._append(device_ns, reference_ns)
        self._refit()
        return True

    def _append(self, device_ns: int, reference_ns: int) -> None:
        self._dev.append(device_ns)
        self._ref.append(reference_ns)

    def _refit(self) -> None:
        d0, r0 = self._dev[-1], self._ref[-1]
        lo = min(self._dev)
        # offset only until the pairs span device time (all at one device time, e.g. a
        # datagram repeated, the slope is undefined and the least squares fail)
        if len(self._dev) < self._min_pairs or d0 - lo < self._min_span_ns or lo == max(self._dev):
            offsets = sorted(r - d for d, r in zip(self._dev, self._ref, strict=True))
            self._coef = (d0, d0 + offsets[len(offsets) // 2], 0.0)
            self.residual_ns = float(np.std(np.array(offsets) - offsets[0]))
            self.leverage = 1.0
            self.unfitted_skew_ns = round(MAX_SKEW * (d0 - lo + EXTRAPOLATION_NS))
            return
        self.unfitted_skew_ns = 0
        x = np.array(self._dev, dtype=np.float64) - d0
        y = np.array(self._ref, dtype=np.float64) - r0 - x
        skew, intercept = np.polyfit(x, y, 1)
        dx = x - x.mean()
        self.leverage = float(np.abs(1 / x.size - x.mean() * dx / np.sum(dx**2)).sum())
        if abs(skew) > self._max_skew:
            skew = float(np.clip(skew, -self._max_skew, self._max_skew))
            intercept = float(np.mean(y - skew * x))
            self.leverage = 1.0
        self._coef = (d0, r0 + round(intercept), float(skew))
        self.residual_ns = float(np.sqrt(np.mean((y - (intercept + skew * x)) ** 2)))

    def map(self, device_ns: int) -> int:
        """Reference time of a device time, ns.

        Raises
        ------
        ClockError
            Before ``ready_pairs`` pairs have been added.
        """
        if not self.ready:
            raise ClockError("device clock not synchronised yet (too few time references)")
        return self._map(device_ns)

    def _map(self, device_ns: int) -> int:
        assert self._coef is not None
        d0, r0, skew = self._coef
        dx = device_ns - d0
        return r0 + dx + round(skew * dx)


@dataclass(frozen=True)
class TimesyncExchange:
    """One TIMESYNC round trip.

    Attributes
    ----------
    local_send_ns, local_recv_ns : int
        Local clock at request send and response receive, ns.
    remote_ns : int
        Remote clock in the response (``tc1``), ns.
    """

    local_send_ns: int
    local_recv_ns: int
    remote_ns: int

    @property
    def rtt_ns(self) -> int:
        """Round-trip time, ns."""
        return self.local_recv_ns - self.local_send_ns

    @property
    def midpoint_ns(self) -> int:
        """Local time assumed to match ``remote_ns`` (symmetric path), ns."""
        return (self.local_send_ns + self.local_recv_ns) // 2


class TimesyncEstimator:
    """Maps a remote (autopilot boot) clock onto the local clock from TIMESYNC exchanges.

    Parameters
    ----------
    window : int
        Exchanges kept: the sliding window over which the minimum round trip is
        taken and the clock fitted (32 at the MAVLink source's 4 Hz: 8 s).
    rtt_margin_ns : int
        Minimum-round-trip filter: only exchanges whose round trip is at most the
        window's minimum plus this enter the fit, ns (see Notes).
    max_rtt_ns : int
        Exchanges slower than this are discarded outright, ns.
    outlier_ns : int
        An admitted exchange further than this from the fit of the earlier ones is
        rejected; half a window of them in a row means the remote clock stepped and
        the fit restarts from them (:class:`LinearClockFit`), ns.
    ready_exchanges : int
        Exchanges in the window before :meth:`to_local` answers: the minimum of
        one round trip is no minimum (the first request often waits while the
        peer starts up).
    min_span_ns : int
        Remote time the admitted exchanges must span before the skew is fitted, ns
        (offset only before that; see :class:`LinearClockFit`).

    Notes
    -----
    Minimum-round-trip filter, as NTP's clock filter and PX4's timesync. The remote
    stamp ``tc1`` is taken between our send ``t_s`` and our receive ``t_r``, so an
    exchange's midpoint ``(t_s + t_r) / 2`` differs from the local time of ``tc1``
    by ``(d_out - d_back) / 2``, the one-way delays' asymmetry. A loaded host (or a
    queue on the link) delays one leg: with ``d_out = a + x`` and ``d_back = b + y``
    (``a``, ``b`` the unloaded delays, ``x``, ``y`` ≥ 0 the queueing), the error is
    ``(a - b) / 2 + (x - y) / 2`` and ``|x - y| ≤ x + y = RTT - a - b``. An exchange
    admitted with ``RTT ≤ RTT_min + rtt_margin_ns`` (``RTT_min``: the smallest round
    trip in the window) therefore carries at most ``rtt_margin_ns / 2`` more
    queueing error than the fastest one, however long the delays of the others; a
    fastest-fraction rule would admit delayed exchanges whenever most of the window
    is delayed (a loaded host). The admitted exchanges are fitted for offset and skew
    (:class:`LinearClockFit`, skew clipped at :data:`MAX_SKEW`).

    :attr:`bound_ns` is half the slowest admitted round trip (causality: the remote
    instant lies between send and receive, so no midpoint is further off) times the fit's
    leverage at the newest exchange (:attr:`LinearClockFit.leverage`: a line through the
    midpoints can add up their errors), plus three times the fit's RMS residual, plus,
    while the skew is not fitted yet, what a skew of :data:`MAX_SKEW` can do over the
    exchanges' span and :data:`EXTRAPOLATION_NS` beyond them.
    A remote clock that goes back by more than ``max_rtt_ns`` is a reboot and resets
    the estimate; a smaller step back is a response overtaken by a later one (no
    exchange is slower than ``max_rtt_ns``) and is kept.
    """

    def __init__(
        self,
        window: int = 32,
        rtt_margin_ns: int = 500_000,
        max_rtt_ns: int = 200_000_000,
        outlier_ns: int = 5_000_000,
        ready_exchanges: int = 3,
        min_span_ns: int = 2_000_000_000,
    ) -> None:
        self._window: deque[TimesyncExchange] = deque(maxlen=window)
        self._margin = rtt_margin_ns
        self._max_rtt = max_rtt_ns
        self._ready_exchanges = ready_exchanges
        self._fit = LinearClockFit(
            window=window, outlier_ns=outlier_ns, min_pairs=4, min_span_ns=min_span_ns
        )
        self._fit_rtt_ns = 0
        self.rejected = 0
        """Exchanges discarded (round trip negative or over ``max_rtt_ns``) or not
        admitted to the fit when they arrived."""
        self.resets = 0

    @property
    def ready(self) -> bool:
        """Whether ``ready_exchanges`` exchanges are in the window, so :meth:`to_local` answers."""
        return self._fit.ready and len(self._window) >= self._ready_exchanges

    @property
    def bound_ns(self) -> int:
        """Stated bound on the error of :meth:`to_local`, ns."""
        fit = self._fit
        return round(fit.leverage * self._fit_rtt_ns / 2 + 3 * fit.residual_ns) + (
            fit.unfitted_skew_ns
        )

    def reset(self) -> None:
        """Forget every exchange (remote reboot)."""
        self._window.clear()
        self._fit.reset()
        self.resets += 1

    def add(self, ex: TimesyncExchange) -> bool:
        """Add one exchange; returns False when it is discarded or not admitted to the fit."""
        if ex.rtt_ns < 0 or ex.rtt_ns > self._max_rtt:
            self.rejected += 1
            return False
        if self._window and ex.remote_ns < self._window[-1].remote_ns - self._max_rtt:
            self.reset()
        self._window.append(ex)
        rtt_min = min(e.rtt_ns for e in self._window)
        admitted = sorted(
            (e for e in self._window if e.rtt_ns <= rtt_min + self._margin),
            key=lambda e: e.remote_ns,
        )
        self._fit.reset()
        accepted = False
        for e in admitted:
            ok = self._fit.add(e.remote_ns, e.midpoint_ns)
            accepted = ok if e is ex else accepted
        self._fit_rtt_ns = max(e.rtt_ns for e in admitted)
        if not accepted:
            self.rejected += 1
        return accepted

    def to_local(self, remote_ns: int) -> int:
        """Local clock time of a remote clock time, ns.

        Raises
        ------
        ClockError
            Before ``ready_exchanges`` exchanges.
        """
        if not self.ready:
            raise ClockError("TIMESYNC not settled yet (too few exchanges)")
        return self._fit.map(remote_ns)
