"""A device's wrapping clock mapped onto GPS time, with a queue for early samples.

Shared by the SBG serial and SBG CAN decoders: samples are built with their
device time, then stamped with GPS time once the device has reported a time
reference; until then they wait in a bounded queue.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import deque
from typing import Protocol

from sarmoco.drivers.counters import DriverCounters
from sarmoco.drivers.samples import Sample, TimeSample, Validity
from sarmoco.drivers.timesync import CounterUnwrapper, LinearClockFit

log = logging.getLogger(__name__)

REBOOT_BACKSTEP_US = 2_000_000
"""A device clock stepping back more than this (and not wrapping) has rebooted, µs."""


class ClockModel(Protocol):
    """What :class:`DeviceClock` needs from a clock model (device ns → GPS ns)."""

    @property
    def ready(self) -> bool:
        """Whether :meth:`map` can answer."""

    def add(self, device_ns: int, reference_ns: int) -> bool:
        """Add a (device, GPS) pair; False if rejected."""

    def map(self, device_ns: int) -> int:
        """GPS ns of a device time."""

    def reset(self) -> None:
        """Forget everything (device reboot)."""


class DeviceClock:
    """Maps a wrapping device clock onto GPS ns and stamps samples with it.

    Parameters
    ----------
    link : str
        Name used in log messages.
    counters : DriverCounters
        Reboots count as gaps; samples dropped from a full queue as drops.
    max_pending : int
        Samples kept while no time reference has arrived yet.
    model : ClockModel or None
        The device → GPS model; default a :class:`LinearClockFit` rejecting
        pairs more than 1 ms off.
    tick_ns : int
        Duration of one device clock tick, ns (1000 for µs, 10^6 for ms).
    bits : int
        Width of the wrapping device counter.
    """

    def __init__(
        self,
        link: str,
        counters: DriverCounters,
        max_pending: int = 4000,
        model: ClockModel | None = None,
        tick_ns: int = 1000,
        bits: int = 32,
    ) -> None:
        self._link = link
        self._counters = counters
        self.fit: ClockModel = model or LinearClockFit(window=16, outlier_ns=1_000_000)
        self._tick_ns = tick_ns
        self._unwrap = CounterUnwrapper(bits, REBOOT_BACKSTEP_US * 1000 // tick_ns)
        self._pending: deque[Sample] = deque()
        self._last: dict[str, int] = {}
        self._max_pending = max_pending
        self.valid = False
        """Whether the last reference came from a device clock it calls valid."""

    def device_ns(self, raw: int) -> int:
        """Unwrapped device time of a raw counter value (ticks), ns; resets the fit on reboot."""
        ext, reset = self._unwrap.unwrap(raw)
        if reset:
            log.warning(
                "%s: device clock went backwards: device rebooted, clock fit reset", self._link
            )
            self.fit.reset()
            self._last.clear()
            self._counters.gaps += 1
        return ext * self._tick_ns

    def reference(self, device_ns: int, gps_ns: int, valid: bool, source: str) -> TimeSample | None:
        """Add a (device, GPS) pair; returns the TimeSample when the pair is accepted."""
        self.valid = valid
        if not self.fit.add(device_ns, gps_ns):
            return None
        return TimeSample(gps_ns, device_ns, Validity.TIME if valid else Validity.NONE, source)

    def stamp(self, sample: Sample, out: list[Sample]) -> None:
        """Append ``sample`` to ``out`` with its GPS time, or queue it until the clock is ready.

        A sample not later (on the device clock) than the last one of the same
        source is a duplicate or arrived out of order: it is dropped and
        counted, so each source's times increase strictly.
        """
        last = self._last.get(sample.source)
        if last is not None and sample.device_time_ns <= last:
            self._counters.drops += 1
            return
        self._last[sample.source] = sample.device_time_ns
        if not self.fit.ready:
            self._pending.append(sample)
            if len(self._pending) > self._max_pending:
                self._pending.popleft()
                self._counters.drops += 1
            return
        while self._pending:
            out.append(self._mapped(self._pending.popleft()))
        out.append(self._mapped(sample))

    def _mapped(self, s: Sample) -> Sample:
        valid = s.valid | Validity.TIME if self.valid else s.valid
        return dataclasses.replace(s, t_gps_ns=self.fit.map(s.device_time_ns), valid=valid)
