"""Per-driver counters and the log-once-per-burst error reporter.

A driver never dies on what comes off the wire: a bad frame is counted, logged
once at the start of a burst of errors and once when the stream is back in sync,
and decoding goes on.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass


@dataclass
class DriverCounters:
    """Counts kept by every driver (monotonic, never reset while the driver lives).

    Attributes
    ----------
    bytes : int
        Bytes received from the link or file.
    frames : int
        Frames (packets, messages) decoded successfully.
    crc_errors : int
        Frames whose checksum or signature did not match.
    parse_errors : int
        Bytes or frames that could not be parsed (bad header, bad length, bad field).
    gaps : int
        Detected gaps in a sequence (VITA 49 packet count, MAVLink sequence,
        navigation samples missing), counted once per gap.
    drops : int
        Frames known to be lost (the sum of gap sizes where the size is known),
        or frames received but discarded (buffer full, unknown stream).
    rejected : int
        Frames rejected by policy (MAVLink signing, a VITA stream other than the
        configured channel's).
    skipped_bytes : int
        Bytes skipped while resynchronising a byte stream.
    bus_error_states : int
        Times the link's adapter reported its bus in a worse error state than before
        (CAN error warning, error passive, bus-off).
    kernel_drops : int
        Datagrams the operating system discarded because the socket's receive buffer was
        full (UDP links, where the kernel tells): lost before the driver saw them.
    """

    bytes: int = 0
    frames: int = 0
    crc_errors: int = 0
    parse_errors: int = 0
    gaps: int = 0
    drops: int = 0
    rejected: int = 0
    skipped_bytes: int = 0
    bus_error_states: int = 0
    kernel_drops: int = 0

    def snapshot(self) -> dict[str, int]:
        """A copy of the counters as a plain dict (for status and the recorder)."""
        return asdict(self)


class BurstLog:
    """Logs the first error of a burst and the resynchronisation that ends it.

    Parameters
    ----------
    logger : logging.Logger
        Where to log.
    link : str
        Name of the link, used in every message (e.g. ``"sbg /dev/ttyUSB0"``).
    """

    def __init__(self, logger: logging.Logger, link: str) -> None:
        self._logger = logger
        self._link = link
        self._in_burst = False
        self._burst_errors = 0
        self.bursts = 0
        """Number of error bursts seen."""

    def error(self, kind: str, detail: str) -> None:
        """Record one error; logs a warning only if it starts a new burst."""
        self._burst_errors += 1
        if not self._in_burst:
            self._in_burst = True
            self.bursts += 1
            self._logger.warning(
                "%s: %s: %s (further errors quiet until resync)", self._link, kind, detail
            )

    def ok(self) -> None:
        """Record one good frame; ends the current burst, if any, with an info line."""
        if self._in_burst:
            self._logger.info(
                "%s: back in sync after %d bad frame(s)", self._link, self._burst_errors
            )
            self._in_burst = False
            self._burst_errors = 0
