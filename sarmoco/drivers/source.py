"""The one source interface every navigation driver implements.

A source is polled: :meth:`Source.poll` returns the samples decoded from what
arrived within the timeout (possibly none) and never raises on bad input from
the link; link failures (port gone, socket closed) raise
:class:`~sarmoco.errors.DriverError`. File sources return an empty list with
:attr:`Source.eof` set once the file is exhausted. Live, file and simulated
links share the implementation: only the transport differs.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Iterator

from sarmoco.closing import Closing
from sarmoco.drivers.counters import DriverCounters
from sarmoco.drivers.samples import Sample


class Source(Closing):
    """Base class of the navigation sources (MAVLink, SBG serial, SBG CAN)."""

    def __init__(self) -> None:
        self.counters = DriverCounters()
        self.eof = False

    @abstractmethod
    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        """Decode what arrives within ``timeout_s`` seconds; return the new samples."""

    def samples(self, timeout_s: float = 0.1) -> Iterator[Sample]:
        """Iterate over samples until end of file (file sources) or forever (live)."""
        while not self.eof:
            yield from self.poll(timeout_s)
