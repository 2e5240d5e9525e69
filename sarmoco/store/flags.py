"""Per-pulse quality flags, one bit each, recorded with every pulse, and what the nav
buffer did with each navigation sample (:class:`PushResult`, recorded with the sample).

A flag never changes the data: it says what the daemon knows about a pulse
(navigation missing, receiver trouble, pulses lost before it). The processor
decides what to do with flagged pulses; the recorder keeps the flags as
``uint32`` (:data:`FLAG_DTYPE`).
"""

from __future__ import annotations

import enum

import numpy as np
import numpy.typing as npt

from sarmoco.drivers.samples import EchoPackets

FLAG_DTYPE = np.dtype(np.uint32)
"""Storage type of the flags in the ring and in the store."""


class PulseFlag(enum.IntFlag):
    """Quality bits of one pulse."""

    NONE = 0
    NAV_GAP = 1 << 0
    """The INS samples around the pulse are further apart than the longest silence
    bridged (``ins.bridge_gap_s``: a long dropout, samples rejected for a clock
    inconsistency, before the first or after a break): the navigation is not
    interpolated (NaN), the pulse is not focused."""
    NAV_TIMEOUT = 1 << 1
    """No INS sample at or after the pulse arrived within the latency budget:
    the navigation is not interpolated (NaN)."""
    INVALID_DATA = 1 << 2
    """The radar said the samples are not valid (VITA 49 trailer valid-data bit)."""
    SAMPLE_LOSS = 1 << 3
    """The radar lost samples inside this pulse (VITA 49 trailer)."""
    OVER_RANGE = 1 << 4
    """The receiver was over range (VITA 49 trailer)."""
    LOST_BEFORE = 1 << 5
    """Radar packets of this channel were lost on the link before this pulse."""
    DROPPED_BEFORE = 1 << 6
    """The echo ring was full: the daemon dropped pulses before this one."""
    TURN = 1 << 7
    """The platform was turning (the heading averaged over a synthetic aperture changed by
    more than half the azimuth beam within one, :mod:`sarmoco.processing.segments`): the
    pulse was not imaged. Set by the focuser, after the pulse was first recorded."""
    NAV_BRIDGED = 1 << 8
    """The INS samples around the pulse are further apart than ``ins.max_gap_s`` but not
    than ``ins.bridge_gap_s`` (a short INS silence): the navigation was interpolated
    across the silence from the samples on both sides and the pulse was focused."""
    CONTEXT_MISMATCH = 1 << 9
    """The radar's last context packet on this stream disagreed with the configured sample
    rate, bandwidth or RF frequency (VITA 49 context): the pulse was recorded, not focused."""

    @classmethod
    def of_packets(cls, packets: EchoPackets) -> npt.NDArray[np.uint32]:
        """The receiver and link flags of decoded radar packets.

        Parameters
        ----------
        packets : EchoPackets
            Metadata returned by the radar decoder.

        Returns
        -------
        ndarray of uint32 (:data:`FLAG_DTYPE`), shape (P,)
            ``INVALID_DATA``, ``SAMPLE_LOSS``, ``OVER_RANGE``, ``LOST_BEFORE`` and
            ``CONTEXT_MISMATCH`` as they apply to each packet.
        """
        flags = np.zeros(len(packets), FLAG_DTYPE)
        for flag, on in (
            (cls.INVALID_DATA, ~packets.valid_data),
            (cls.SAMPLE_LOSS, packets.sample_loss),
            (cls.OVER_RANGE, packets.over_range),
            (cls.LOST_BEFORE, packets.lost_before != 0),
            (cls.CONTEXT_MISMATCH, packets.context_mismatch),
        ):
            flags[on] |= FLAG_DTYPE.type(flag)
        return flags


NAV_UNUSABLE = PulseFlag.NAV_GAP | PulseFlag.NAV_TIMEOUT
"""Flags under which a pulse has no navigation solution (NaN motion)."""
NAV_FLAGS = NAV_UNUSABLE | PulseFlag.NAV_BRIDGED
"""Flags the aligner sets (after the pulse was first recorded)."""
UNFOCUSABLE = NAV_UNUSABLE | PulseFlag.CONTEXT_MISMATCH
"""Flags under which a pulse is recorded but not focused (its echo blanked)."""


class PushResult(enum.IntEnum):
    """What a nav buffer stream did with a pushed sample (recorded with the sample)."""

    ACCEPTED = 0
    DUPLICATE = 1
    STALE = 2
    CLOCK_REJECTED = 3
