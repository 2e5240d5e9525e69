"""A device's wrapping microsecond clock mapped onto GPS time, with a queue for early samples.

Shared by the SBG serial and SBG CAN decoders: samples are built with their
device time, then stamped with GPS time once the device has reported a time
reference; until then they wait in a bounded queue.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import deque

from sarmoco.drivers.counters import DriverCounters
from sarmoco.drivers.samples import Sample, TimeSample, Validity
from sarmoco.drivers.timesync import CounterUnwrapper, LinearClockFit

log = logging.getLogger(__name__)

REBOOT_BACKSTEP_US = 2_000_000
"""A device clock stepping back more than this (and not wrapping) has rebooted, µs."""


class DeviceClock:
    """Maps a 32-bit µs device clock onto GPS ns and stamps samples with it.

    Parameters
    ----------
    link : str
        Name used in log messages.
    counters : DriverCounters
        Reboots count as gaps; samples dropped from a full queue as drops.
    max_pending : int
        Samples kept while no time reference has arrived yet.
    outlier_ns : int
        Reference pairs disagreeing with the fit by more than this are rejected.
    """

    def __init__(
        self,
        link: str,
        counters: DriverCounters,
        max_pending: int = 4000,
        outlier_ns: int = 1_000_000,
    ) -> None:
        self._link = link
        self._counters = counters
        self.fit = LinearClockFit(window=16, outlier_ns=outlier_ns)
        self._unwrap = CounterUnwrapper(32, REBOOT_BACKSTEP_US)
        self._pending: deque[Sample] = deque()
        self._max_pending = max_pending
        self.valid = False
        """Whether the last reference came from a device clock it calls valid."""

    def device_ns(self, raw_us: int) -> int:
        """Unwrapped device time of a raw 32-bit µs stamp, ns (resets the fit on reboot)."""
        ext_us, reset = self._unwrap.unwrap(raw_us)
        if reset:
            log.warning(
                "%s: device clock went backwards: device rebooted, clock fit reset", self._link
            )
            self.fit.reset()
            self._counters.gaps += 1
        return ext_us * 1000

    def reference(self, device_ns: int, gps_ns: int, valid: bool, source: str) -> TimeSample | None:
        """Add a (device, GPS) pair; returns the TimeSample when the pair is accepted."""
        self.valid = valid
        if not self.fit.add(device_ns, gps_ns):
            return None
        return TimeSample(gps_ns, device_ns, Validity.TIME if valid else Validity.NONE, source)

    def stamp(self, sample: Sample, out: list[Sample]) -> None:
        """Append ``sample`` to ``out`` with its GPS time, or queue it until the clock is ready."""
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
