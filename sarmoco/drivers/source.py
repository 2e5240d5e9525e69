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
    """Base class of the navigation sources (MAVLink, SBG serial, SBG CAN).

    Attributes
    ----------
    raw_format : str
        What :meth:`take_raw` returns, concatenated over calls: ``"tlog"`` (MAVLink
        frames each after an 8-byte big-endian receive time in UNIX µs, a telemetry
        log), ``"sbgecom"`` (the bytes as read from the serial line or file),
        ``"candump"`` (``candump -L`` log lines); empty when the source keeps none.
    bus_fault : str
        What the link's adapter reports wrong with its bus now (e.g. a CAN adapter
        bus-off); empty when nothing is, or the link reports nothing.
    """

    raw_format = ""

    def __init__(self) -> None:
        self.counters = DriverCounters()
        self.eof = False
        self.bus_fault = ""
        self._raw: bytearray | None = None

    def keep_raw(self) -> bool:
        """Keep what is received, as :attr:`raw_format`, for :meth:`take_raw` from now on.

        Returns
        -------
        bool
            False when this source keeps no raw bytes (empty :attr:`raw_format`).
        """
        if not self.raw_format:
            return False
        self._raw = bytearray()
        return True

    @property
    def keeping_raw(self) -> bool:
        """Whether :meth:`keep_raw` took effect (received bytes are kept as :attr:`raw_format`)."""
        return self._raw is not None

    def take_raw(self) -> bytes:
        """What was received since the last call (``b""`` unless :meth:`keep_raw` was called).

        Call it after each :meth:`poll` (from the same thread): the bytes wait here.
        """
        if not self._raw:
            return b""
        data = bytes(self._raw)
        self._raw.clear()
        return data

    def _keep(self, data: bytes) -> None:
        """Add received bytes for :meth:`take_raw` (no-op unless :meth:`keep_raw` was called)."""
        if self._raw is not None:
            self._raw += data

    @abstractmethod
    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        """Decode what arrives within ``timeout_s`` seconds; return the new samples."""

    def samples(self, timeout_s: float = 0.1) -> Iterator[Sample]:
        """Iterate over samples until end of file (file sources) or forever (live)."""
        while not self.eof:
            yield from self.poll(timeout_s)
