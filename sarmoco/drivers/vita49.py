"""VITA 49.2 radar echo packets: the pure encoder and decoder (no I/O).

Profile (what sarmoco reads and what its simulator writes; docs/integrator.md, "The radar:
VITA 49.2 profile"):

* Signal data packet with stream ID (packet type 1), one pulse per packet,
  stream ID = receive channel. Class ID present (any OUI accepted), trailer present.
* TSI = 1 (UTC: POSIX seconds since 1970-01-01) or 2 (GPS: seconds since
  1980-01-06); TSF = 2 (real-time picoseconds within the second). The timestamp is
  the **transmit time** of the pulse; the range-gate delay comes from configuration.
* 4-bit packet count per stream, checked for loss.
* Payload: interleaved I/Q, signed 16-bit or IEEE-754 float32, big-endian.
* Trailer: valid-data (enable bit 30 / indicator bit 18), over-range (25 / 13) and
  sample-loss (24 / 12) indicators are read when enabled.
* Context packets (type 4) with CIF0 bandwidth (bit 29: the usable band of the digitised
  signal, :class:`ContextExpectation`), RF reference frequency (bit 27) and sample rate
  (bit 21), each 64-bit two's complement with 20 fractional bits, Hz; checked against
  configuration when expectations are given.
  A context packet that disagrees marks its stream: the signal packets after it carry
  ``context_mismatch`` until a context packet agrees again (counted, logged).

Every length in a header is checked against the packet before anything is sliced;
the payload is converted by numpy straight into the caller's preallocated row.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from sarmoco.drivers.clock import NS_PER_S, gps_ns_to_unix_ns, unix_ns_to_gps_ns
from sarmoco.drivers.counters import BurstLog, DriverCounters
from sarmoco.drivers.samples import EchoPacket, EchoPackets
from sarmoco.errors import ConfigError

log = logging.getLogger(__name__)

PayloadFormat = Literal["int16", "float32"]
TimeBase = Literal["gps", "utc"]

TYPE_SIGNAL_SID = 1
TYPE_CONTEXT = 4
TSI_UTC = 1
TSI_GPS = 2
TSF_REALTIME_PS = 2
PS_PER_NS = 1000
MAX_CONTEXT_WORDS = 64
"""Largest context packet accepted, 32-bit words (the profile's needs ~20)."""

_CIF0_BANDWIDTH = 29
_CIF0_RF_REF = 27
_CIF0_SAMPLE_RATE = 21
# Words of each CIF0 field from bit 30 down to bit 21 (the profile reads no further).
_CIF0_FIELD_WORDS = {30: 1, 29: 2, 28: 2, 27: 2, 26: 2, 25: 2, 24: 1, 23: 1, 22: 1, 21: 2}
_CIF_EXTRA_WORD_BITS = (1, 2, 3, 7)
_CIF0_UNREAD = (1 << 21) - 1
"""CIF0 bits of fields (and further CIF words) whose contents the profile does not read: when
none is set, a context packet's size is known to the word (a longer one is damage, e.g. a
header in garbage whose size field swallows the packets after it)."""
_RADIX = float(1 << 20)

_TR_CAL_TIME = (31, 19)
_TR_VALID = (30, 18)
_TR_OVER_RANGE = (25, 13)
_TR_SAMPLE_LOSS = (24, 12)

_U32 = struct.Struct(">I")
_Q64 = struct.Struct(">Q")
_Q64S = struct.Struct(">q")

_SRC_DTYPES: dict[str, np.dtype] = {"int16": np.dtype(">i2"), "float32": np.dtype(">f4")}

_FULL_HEADER = np.dtype(
    [("w0", ">u4"), ("sid", ">u4"), ("class_id", ">u8"), ("sec", ">u4"), ("ps", ">u8")]
)
"""Header of a signal packet of the full profile (with class ID), before the payload."""
BATCH_MIN_PACKETS = 32
"""Batches smaller than this are decoded packet by packet (numpy's fixed cost per call)."""
PS_PER_S = 1_000_000_000_000
"""Picoseconds per second: the timestamp fraction is below it."""


def _header_checks(w0: Any, n_bytes: Any) -> tuple[tuple[str, Any], ...]:
    """The profile's checks of a packet's first header word against the packet length.

    Parameters
    ----------
    w0 : int or ndarray of uint32
        First header word (one packet in :meth:`VitaDecoder.decode_into`, or one per
        packet of a batch in :meth:`VitaDecoder.decode_batch`, checked elementwise).
    n_bytes : int or ndarray of int
        Packet length, bytes.

    Returns
    -------
    tuple of (str, bool or ndarray of bool)
        In the order they are reported: what is wrong when a check fails, and whether it
        holds: the announced size is the length, the packet type is in the profile, the
        timestamp is UTC or GPS seconds with a real-time picosecond fraction.
    """
    ptype, tsi, tsf = w0 >> 28, (w0 >> 22) & 3, (w0 >> 20) & 3
    return (
        ("length", (w0 & 0xFFFF) * 4 == n_bytes),
        ("packet type", (ptype == TYPE_SIGNAL_SID) | (ptype == TYPE_CONTEXT)),
        ("timestamp", ((tsi == TSI_UTC) | (tsi == TSI_GPS)) & (tsf == TSF_REALTIME_PS)),
    )


def _header_fault(kind: str, w0: int, n_bytes: int) -> str:
    """How a failed check of :func:`_header_checks` is logged."""
    if kind == "length":
        return f"header says {(w0 & 0xFFFF) * 4} bytes, packet has {n_bytes}"
    if kind == "packet type":
        return f"type {w0 >> 28} is not in the profile (1, 4)"
    return f"TSI {(w0 >> 22) & 3} / TSF {(w0 >> 20) & 3} is not UTC|GPS / real-time ps"


def _fraction_ok(ps: Any) -> Any:
    """Whether a timestamp fraction (ps; int or elementwise array) is below one second."""
    return ps < PS_PER_S


def _timestamp_words(t_gps_ns: int, time_base: TimeBase, leap_s: int) -> tuple[int, int]:
    t = gps_ns_to_unix_ns(t_gps_ns, leap_s) if time_base == "utc" else int(t_gps_ns)
    seconds, ns = divmod(t, NS_PER_S)
    return seconds, ns * PS_PER_NS


def _header_word(ptype: int, trailer: bool, tsi: int, count: int, size_words: int) -> int:
    return (
        (ptype << 28)
        | (1 << 27)
        | (int(trailer) << 26)
        | (tsi << 22)
        | (TSF_REALTIME_PS << 20)
        | ((count & 0xF) << 16)
        | size_words
    )


def encode_signal_packet(
    stream_id: int,
    t_gps_ns: int,
    count: int,
    iq: npt.NDArray[np.generic],
    payload: PayloadFormat = "int16",
    *,
    time_base: TimeBase = "gps",
    leap_s: int = 18,
    oui: int = 0,
    valid_data: bool = True,
    sample_loss: bool = False,
    over_range: bool = False,
) -> bytes:
    """Encode one pulse as a VITA 49.2 signal data packet of this profile.

    Parameters
    ----------
    stream_id : int
        Receive channel, 32-bit.
    t_gps_ns : int
        Transmit time of the pulse, GPS ns.
    count : int
        Packet count of this stream (taken modulo 16).
    iq : ndarray
        Complex samples (any complex dtype, shape (n,)) or interleaved real
        pairs (shape (n, 2) or (2n,)).
    payload : {"int16", "float32"}
        Wire format of I and Q. Complex input is rounded to int16 when ``int16``.
    time_base : {"gps", "utc"}
        TSI written (2 = GPS, 1 = UTC POSIX seconds).
    leap_s : int
        GPS − UTC, s (only used for ``utc``).
    oui : int
        24-bit OUI of the class ID.
    valid_data, sample_loss, over_range : bool
        Trailer indicators (all enabled).
    """
    arr = np.asarray(iq)
    flat = arr.view(arr.real.dtype).reshape(-1) if np.iscomplexobj(arr) else arr.reshape(-1)
    if payload == "int16":
        flat = np.rint(flat) if flat.dtype.kind == "f" else flat
    body = np.ascontiguousarray(flat, dtype=_SRC_DTYPES[payload]).tobytes()
    seconds, ps = _timestamp_words(t_gps_ns, time_base, leap_s)
    size_words = 7 + len(body) // 4 + 1
    tsi = TSI_UTC if time_base == "utc" else TSI_GPS
    enables = (1 << _TR_CAL_TIME[0]) | (1 << _TR_VALID[0]) | (1 << _TR_OVER_RANGE[0])
    enables |= 1 << _TR_SAMPLE_LOSS[0]
    ind = (1 << _TR_CAL_TIME[1]) | (int(valid_data) << _TR_VALID[1])
    ind |= (int(over_range) << _TR_OVER_RANGE[1]) | (int(sample_loss) << _TR_SAMPLE_LOSS[1])
    packet_class = 1 if payload == "int16" else 2
    head = struct.pack(
        ">IIIIIQ",
        _header_word(TYPE_SIGNAL_SID, True, tsi, count, size_words),
        stream_id & 0xFFFFFFFF,
        oui & 0xFFFFFF,
        packet_class,
        seconds & 0xFFFFFFFF,
        ps,
    )
    return head + body + _U32.pack(enables | ind)


def encode_context_packet(
    stream_id: int,
    t_gps_ns: int,
    count: int,
    *,
    bandwidth_hz: float,
    rf_reference_hz: float,
    sample_rate_hz: float,
    time_base: TimeBase = "gps",
    leap_s: int = 18,
    oui: int = 0,
) -> bytes:
    """Encode a context packet (type 4) with CIF0 bandwidth, RF reference frequency, sample rate.

    Frequencies are in Hz and quantised to 2^-20 Hz.
    """
    cif0 = (1 << _CIF0_BANDWIDTH) | (1 << _CIF0_RF_REF) | (1 << _CIF0_SAMPLE_RATE)
    fields = b"".join(
        _Q64S.pack(round(v * _RADIX)) for v in (bandwidth_hz, rf_reference_hz, sample_rate_hz)
    )
    seconds, ps = _timestamp_words(t_gps_ns, time_base, leap_s)
    size_words = 7 + 1 + len(fields) // 4
    tsi = TSI_UTC if time_base == "utc" else TSI_GPS
    head = struct.pack(
        ">IIIIIQI",
        _header_word(TYPE_CONTEXT, False, tsi, count, size_words),
        stream_id & 0xFFFFFFFF,
        oui & 0xFFFFFF,
        0,
        seconds & 0xFFFFFFFF,
        ps,
        cif0,
    )
    return head + fields


@dataclass(frozen=True)
class ContextExpectation:
    """Radar parameters from configuration that context packets must agree with.

    VITA 49.2 describes, in a context packet, the signal digitised in its stream: the
    Bandwidth field (CIF0 bit 29) is the usable band of that digitised signal, the RF
    Reference Frequency (bit 27) the RF frequency translated to it, the Sample Rate (bit 21)
    the rate of its samples. So the bandwidth a digitiser reports is not the chirp's in
    general: a pulsed-LFM receiver that samples the whole chirp reports a band that holds
    the chirp (its bandwidth up to the sample rate, e.g. its anti-alias filter's); a dechirp
    (stretch) receiver digitises the beat band, its IF, a small part of the chirp's. Either
    way complex (I/Q) samples at the rate ``f_s`` hold at most a band ``f_s``. The bandwidth
    agrees with configuration when it lies in ``bandwidth_hz`` (:meth:`for_receiver`).

    Attributes
    ----------
    bandwidth_hz : tuple of float
        Lowest and highest digitised bandwidth that agree, Hz.
    rf_reference_hz, sample_rate_hz : float
        Expected values, Hz.
    rel_tol : float
        Allowed relative difference (for the bandwidth: beyond its two bounds).
    """

    bandwidth_hz: tuple[float, float]
    rf_reference_hz: float
    sample_rate_hz: float
    rel_tol: float = 1e-6

    @classmethod
    def for_receiver(
        cls,
        receive: Literal["matched", "dechirp"],
        chirp_bandwidth_hz: float,
        rf_reference_hz: float,
        sample_rate_hz: float,
    ) -> ContextExpectation:
        """The expectation for a configured receiver (class notes).

        Parameters
        ----------
        receive : {"matched", "dechirp"}
            ``matched``: the digitised band must hold the chirp (as much of it as the sample
            rate can) and fit in the sample rate, ``[min(chirp_bandwidth_hz,
            sample_rate_hz), sample_rate_hz]``; ``dechirp``: the beat band, anything
            up to the sample rate, ``(0, sample_rate_hz]`` (the range gate of a dechirp
            receiver spans the beat band ``f_s`` over the chirp rate; a narrower IF filter
            darkens the far ranges but leaves the pulses right).
        chirp_bandwidth_hz, rf_reference_hz, sample_rate_hz : float
            Transmitted chirp bandwidth, carrier and complex sample rate, Hz.
        """
        low = min(chirp_bandwidth_hz, sample_rate_hz) if receive == "matched" else 0.0
        return cls((low, sample_rate_hz), rf_reference_hz, sample_rate_hz)


@dataclass
class VitaCounters(DriverCounters):
    """:class:`~sarmoco.drivers.counters.DriverCounters` and what only a radar stream counts.

    Attributes
    ----------
    context_changes : int
        Context packets that changed a stream from agreeing with the configured radar
        parameters to disagreeing (or from one disagreeing value to another).
    context_mismatch : int
        Signal packets decoded while their stream's last context disagreed with the
        configuration (returned with ``context_mismatch``: recorded, never focused).
    """

    context_changes: int = 0
    context_mismatch: int = 0


@dataclass(frozen=True)
class ContextValues:
    """Values read from the last context packet of a stream (None when absent)."""

    stream_id: int
    t_gps_ns: int
    bandwidth_hz: float | None
    rf_reference_hz: float | None
    sample_rate_hz: float | None


class VitaDecoder:
    """Decodes packets of this profile into rows of a caller-provided array.

    Parameters
    ----------
    n_samples : int
        Complex samples per pulse (from configuration); a packet with another
        payload size is rejected.
    payload : {"int16", "float32"}
        Wire format of I and Q.
    leap_s : int
        GPS − UTC, s, for packets stamped in UTC.
    expect : ContextExpectation or None
        If given, each context packet is checked against it.
    link : str
        Name used in log messages.
    stream_id : int or None
        Accept the signal packets of this VITA stream ID only (one receive channel);
        signal packets of other streams are counted in ``counters.rejected`` and
        skipped (logged once per stream). None: every stream, or with ``first_stream``
        the first one whose signal packet arrives.
    first_stream : bool
        With ``stream_id`` None: take the stream of the first well-formed signal packet
        (logged with its ID) and only that stream from then on.

    Notes
    -----
    Bad packets are counted in :attr:`counters` and logged once per burst; they
    never raise. A context packet that disagrees with ``expect`` (the radar changed its
    sample rate, bandwidth or RF frequency mid-stream, or was never set up as
    configured) is logged as an error naming the field, counted
    (``context_changes``), and marks its stream: every signal packet of that stream
    after it is returned with ``context_mismatch`` (counted in ``context_mismatch``),
    because range compression and focusing with the configured parameters would be
    wrong for it, until a context packet agrees with the configuration again (logged).
    The samples are still decoded: the pulses are recorded for the ground, flagged.
    """

    def __init__(
        self,
        n_samples: int,
        payload: PayloadFormat = "int16",
        *,
        leap_s: int = 18,
        expect: ContextExpectation | None = None,
        link: str = "vita49",
        stream_id: int | None = None,
        first_stream: bool = False,
    ) -> None:
        if n_samples < 1:
            raise ConfigError(f"radar.n_samples: {n_samples!r} is not >= 1")
        if payload not in _SRC_DTYPES:
            raise ConfigError(f"radar.payload: {payload!r} is not one of 'int16', 'float32'")
        self.n_samples = n_samples
        self.payload: PayloadFormat = payload
        self.leap_s = leap_s
        self.expect = expect
        self.stream_id = stream_id
        self.first_stream = first_stream and stream_id is None
        """Whether the stream is still to be chosen: the first signal packet's."""
        self.skipped_streams: set[int] = set()
        """Stream IDs whose signal packets were skipped (each logged once)."""
        self.counters = VitaCounters()
        self.context: dict[int, ContextValues] = {}
        self.mismatch: dict[int, str] = {}
        """Streams whose last context packet disagrees with ``expect``: what it said."""
        self._src_dtype = _SRC_DTYPES[payload]
        self._payload_bytes = 2 * n_samples * self._src_dtype.itemsize
        self._last_count: dict[tuple[int, int], int] = {}
        self._burst = BurstLog(log, link)
        self.last_ok = False
        """Whether the last packet given to :meth:`decode_into` was well formed (accepted, or
        skipped as another stream's)."""

    @property
    def max_packet_bytes(self) -> int:
        """Largest packet this decoder accepts, bytes (the frame limit)."""
        return max(4 * 8 + self._payload_bytes, 4 * MAX_CONTEXT_WORDS)

    def expected_words(self, header: int) -> int | None:
        """Packet size in words implied by a header word, or None if it is not of this profile.

        Used by stream framers to resynchronise: only headers announcing
        exactly the size this profile produces are plausible.
        """
        ptype = header >> 28
        size = header & 0xFFFF
        if ptype == TYPE_SIGNAL_SID:
            words = 2 + 2 * ((header >> 27) & 1) + 3 + ((header >> 26) & 1)
            return size if size == words + self._payload_bytes // 4 else None
        if ptype == TYPE_CONTEXT:
            return size if 3 <= size <= MAX_CONTEXT_WORDS else None
        return None

    def check_row(self, out_row: npt.NDArray[np.generic]) -> npt.NDArray[np.generic]:
        """Validate a destination row and return the flat real view written into."""
        if not out_row.flags.c_contiguous:
            raise ConfigError(f"radar ring row: {out_row.shape} is not C-contiguous")
        flat: npt.NDArray[np.generic]
        if out_row.dtype == np.complex64:
            flat = out_row.view(np.float32)
        elif out_row.dtype == np.int16 and self.payload == "int16":
            flat = out_row.reshape(-1)
        else:
            raise ConfigError(
                f"radar ring dtype: {out_row.dtype} cannot hold {self.payload} I/Q "
                "(use complex64, or int16 for int16 payloads)"
            )
        if flat.size != 2 * self.n_samples:
            raise ConfigError(
                f"radar ring row: {out_row.shape} {out_row.dtype} is not a row of "
                f"{self.n_samples} complex samples"
            )
        return flat

    def _bad(self, kind: str, detail: str) -> None:
        self.counters.parse_errors += 1
        self._burst.error(kind, detail)

    def _time(self, tsi: Any, seconds: Any, ps: Any) -> Any:
        """GPS ns of timestamps: TSI, integer seconds and picoseconds (ints, or int64 arrays
        elementwise)."""
        utc_to_gps_ns = unix_ns_to_gps_ns(0, self.leap_s)
        t = seconds * NS_PER_S + (ps + PS_PER_NS // 2) // PS_PER_NS
        return t + (tsi == TSI_UTC) * utc_to_gps_ns

    def _count(self, ptype: int, stream_id: int, count: int) -> int:
        key = (ptype, stream_id)
        last = self._last_count.get(key)
        self._last_count[key] = count
        if last is None:
            return 0
        lost = _lost(count, last)
        if lost:
            self.counters.gaps += 1
            self.counters.drops += lost
        return lost

    def decode_into(
        self, packet: bytes | bytearray | memoryview, out_row: npt.NDArray[np.generic]
    ) -> EchoPacket | None:
        """Decode one packet; signal data go into ``out_row``.

        Parameters
        ----------
        packet : bytes-like
            Exactly one packet (a datagram, or a slice from a stream framer).
        out_row : ndarray
            Destination: complex64 of shape (n_samples,), or int16 of shape
            (n_samples, 2) for int16 payloads. Written only when a signal packet
            is accepted.

        Returns
        -------
        EchoPacket or None
            Metadata of the pulse; None for a context packet or a rejected packet.
        """
        n = len(packet)
        self.counters.bytes += n
        self.last_ok = False
        if n < 20 or n % 4:
            self._bad("short packet", f"{n} bytes")
            return None
        w0 = _U32.unpack_from(packet, 0)[0]
        for kind, ok in _header_checks(w0, n):
            if not ok:
                self._bad(kind, _header_fault(kind, w0, n))
                return None
        ptype, tsi = w0 >> 28, (w0 >> 22) & 3
        has_class = (w0 >> 27) & 1
        trailer = (w0 >> 26) & 1 if ptype == TYPE_SIGNAL_SID else 0
        pos = 8 + 8 * has_class
        if pos + 12 + 4 * trailer > n:
            self._bad("length", f"{n} bytes cannot hold the announced header")
            return None
        stream_id = _U32.unpack_from(packet, 4)[0]
        seconds = _U32.unpack_from(packet, pos)[0]
        ps = _Q64.unpack_from(packet, pos + 4)[0]
        if not _fraction_ok(ps):
            self._bad("timestamp", f"fractional {ps} ps is not < 1 s")
            return None
        t_ns = self._time(tsi, seconds, ps)
        pos += 12
        count = (w0 >> 16) & 0xF
        if ptype == TYPE_CONTEXT:
            if self._context(packet, pos, stream_id, t_ns):
                self._count(ptype, stream_id, count)
                self.last_ok = True
            return None
        if self.first_stream:
            self._choose_stream(stream_id)
        if not self._accepts(stream_id):
            self._skip_stream(stream_id)
            self.last_ok = True  # well formed: a framer steps past the whole packet
            return None
        if n - pos - 4 * trailer != self._payload_bytes:
            self._bad(
                "payload size",
                f"{n - pos - 4 * trailer} bytes, configured {self._payload_bytes} "
                f"({self.n_samples} {self.payload} I/Q samples)",
            )
            return None
        valid, loss, over = True, False, False
        if trailer:
            tr = _U32.unpack_from(packet, n - 4)[0]
            valid = _indicator(tr, _TR_VALID, True)
            loss = _indicator(tr, _TR_SAMPLE_LOSS, False)
            over = _indicator(tr, _TR_OVER_RANGE, False)
        flat = self.check_row(out_row)
        src = np.frombuffer(packet, dtype=self._src_dtype, count=2 * self.n_samples, offset=pos)
        np.copyto(flat, src, casting="same_kind")
        lost = self._count(ptype, stream_id, count)
        self.counters.frames += 1
        self._burst.ok()
        self.last_ok = True
        return EchoPacket(
            stream_id, t_ns, count, self.n_samples, valid, loss, over, lost,
            self._mismatched(stream_id),
        )  # fmt: skip

    def _mismatched(self, stream_id: int) -> bool:
        """Whether a signal packet of ``stream_id`` comes under a disagreeing context
        (counted in ``context_mismatch``)."""
        if stream_id not in self.mismatch:
            return False
        self.counters.context_mismatch += 1
        return True

    def _accepts(self, stream_id: Any) -> Any:
        """Whether signal packets of ``stream_id`` are decoded (int, or elementwise array)."""
        return True if self.stream_id is None else stream_id == self.stream_id

    def _choose_stream(self, stream_id: int) -> None:
        """Take ``stream_id``, the first signal stream seen, as the one decoded."""
        self.stream_id, self.first_stream = stream_id, False
        log.info(
            "radar: decoding VITA stream 0x%08x (%d), the first signal stream seen "
            "(radar.stream_id selects another)",
            stream_id,
            stream_id,
        )

    def _skip_stream(self, stream_id: int) -> None:
        self.counters.rejected += 1
        if stream_id not in self.skipped_streams:
            self.skipped_streams.add(stream_id)
            log.warning(
                "radar: skipping the signal packets of VITA stream 0x%08x (%d): only stream "
                "0x%08x (%d) is decoded (radar.stream_id selects it; counted in rejected)",
                stream_id,
                stream_id,
                self.stream_id,
                self.stream_id,
            )

    def decode_batch(
        self,
        stage: npt.NDArray[np.uint8],
        lengths: Sequence[int] | npt.NDArray[np.integer],
        out: npt.NDArray[np.generic],
    ) -> EchoPackets:
        """Decode packets received into the rows of ``stage``; same result as :meth:`decode_into`.

        Parameters
        ----------
        stage : ndarray of uint8, shape (>= len(lengths), row_bytes)
            Packet ``i`` is ``stage[i, :lengths[i]]``.
        lengths : sequence or ndarray of int
            Length of each packet, bytes.
        out : ndarray
            Destination rows (as for :meth:`decode_into`), at least ``len(lengths)``;
            accepted pulses fill ``out[0], out[1], ...`` in packet order.

        Returns
        -------
        EchoPackets
            Metadata of the pulses written, in row order.

        Notes
        -----
        From :data:`BATCH_MIN_PACKETS` packets on, runs of signal packets of the
        full profile (class ID and trailer present, the configured size) have
        their headers checked, their payloads converted and their metadata and
        counters worked out with a few numpy calls per run, whatever its length;
        anything else (context packets, damage) goes through :meth:`decode_into`
        in its place in the order.
        """
        k = len(lengths)
        end = _FULL_HEADER.itemsize + self._payload_bytes
        got = _Gathered(self.n_samples)
        slow = k < BATCH_MIN_PACKETS or self.first_stream  # the stream is chosen packet by packet
        if slow or not out.flags.c_contiguous or stage.shape[1] < end + 4:
            for i in range(k):
                got.add(self.decode_into(memoryview(stage[i])[: lengths[i]], out[got.rows]))
            return got.packets()
        flat_dtype = self.check_row(out[0]).dtype
        hdr = stage[:k, : _FULL_HEADER.itemsize].view(_FULL_HEADER)[:, 0]
        w0, n = hdr["w0"], np.asarray(lengths)[:k]
        # the checks decode_into makes, on every header at once; then what makes a packet
        # one of the full profile's signal packets (type, class ID and trailer, size)
        fast = np.logical_and.reduce([ok for _, ok in _header_checks(w0, n)])
        fast &= _fraction_ok(hdr["ps"]) & self._accepts(hdr["sid"])
        fast &= ((w0 >> 28) == TYPE_SIGNAL_SID) & (((w0 >> 26) & 3) == 3) & (n == end + 4)
        trailer = stage[:k, end : end + 4].view(">u4")[:, 0]
        dest = out.reshape(out.shape[0], -1).view(flat_dtype)
        i = 0
        for j in [*np.flatnonzero(~fast).tolist(), k]:  # a slow packet ends a fast run
            if j > i:
                src = stage[i:j, _FULL_HEADER.itemsize : end].view(self._src_dtype)
                np.copyto(dest[got.rows : got.rows + j - i], src, casting="same_kind")
                got.add_run(self._run_metadata(hdr[i:j], trailer[i:j]))
            if j < k:
                got.add(self.decode_into(memoryview(stage[j])[: lengths[j]], out[got.rows]))
            i = j + 1
        return got.packets()

    def _run_metadata(
        self, hdr: npt.NDArray[np.void], trailer: npt.NDArray[np.uint32]
    ) -> EchoPackets:
        """Counters and metadata of a run of full-profile signal packets (already checked).

        Parameters
        ----------
        hdr : ndarray of :data:`_FULL_HEADER`, shape (R,)
            Their headers, in arrival order.
        trailer : ndarray of uint32, shape (R,)
            Their trailer words.
        """
        w0 = hdr["w0"].astype(np.int64)
        sid = hdr["sid"].astype(np.int64)
        ps = hdr["ps"].astype(np.int64)
        t_ns = self._time((w0 >> 22) & 3, hdr["sec"].astype(np.int64), ps)
        count = ((w0 >> 16) & 0xF).astype(np.uint8)
        lost = np.zeros(w0.shape, np.int64)
        streams = np.unique(sid)
        for stream in streams.tolist():
            mine = sid == stream if streams.size > 1 else slice(None)
            lost[mine] = self._count_run(stream, count[mine])
        mismatch = np.isin(sid, list(self.mismatch)) if self.mismatch else np.zeros(sid.shape, bool)
        self.counters.context_mismatch += int(np.count_nonzero(mismatch))
        self.counters.bytes += sid.size * (_FULL_HEADER.itemsize + self._payload_bytes + 4)
        self.counters.frames += sid.size
        self._burst.ok()
        return EchoPackets(
            self.n_samples, sid, t_ns, count,
            _indicator(trailer, _TR_VALID, True), _indicator(trailer, _TR_SAMPLE_LOSS, False),
            _indicator(trailer, _TR_OVER_RANGE, False), lost, mismatch,
        )  # fmt: skip

    def _count_run(self, stream_id: int, count: npt.NDArray[np.uint8]) -> npt.NDArray[np.int64]:
        """:meth:`_count` of consecutive signal packets of one stream: packets lost before
        each (from the 4-bit counts, modulo 16; 0 for the stream's first packet)."""
        key = (TYPE_SIGNAL_SID, stream_id)
        c = count.astype(np.int64)
        last = self._last_count.get(key)
        self._last_count[key] = int(c[-1])
        lost = _lost(c, np.concatenate([[c[0] - 1 if last is None else last], c[:-1]]))
        self.counters.gaps += int(np.count_nonzero(lost))
        self.counters.drops += int(lost.sum())
        return lost

    def _context(self, packet: bytes | bytearray | memoryview, pos: int, sid: int, t: int) -> bool:
        n = len(packet)
        if pos + 4 > n:
            self._bad("context", "no CIF0 word")
            return False
        cif0 = _U32.unpack_from(packet, pos)[0]
        pos += 4 + 4 * sum((cif0 >> b) & 1 for b in _CIF_EXTRA_WORD_BITS)
        values: dict[int, float] = {}
        for bit in range(30, 20, -1):
            if not (cif0 >> bit) & 1:
                continue
            words = _CIF0_FIELD_WORDS[bit]
            if pos + 4 * words > n:
                self._bad("context", f"CIF0 bit {bit} field runs past the packet end")
                return False
            if words == 2:
                values[bit] = _Q64S.unpack_from(packet, pos)[0] / _RADIX
            pos += 4 * words
        if not cif0 & _CIF0_UNREAD and pos != n:  # every field read: the packet ends here
            self._bad("context", f"{n - pos} bytes after the last field its CIF0 announces")
            return False
        ctx = ContextValues(
            sid,
            t,
            values.get(_CIF0_BANDWIDTH),
            values.get(_CIF0_RF_REF),
            values.get(_CIF0_SAMPLE_RATE),
        )
        self.context[sid] = ctx
        self.counters.frames += 1
        self._burst.ok()
        if self.expect is not None:
            self._check_context(ctx)
        return True

    def _check_context(self, ctx: ContextValues) -> None:
        """Mark or clear the stream's mismatch (class notes); log each change once."""
        assert self.expect is not None
        tol = self.expect.rel_tol
        wrong = []
        low, high = self.expect.bandwidth_hz
        band = ctx.bandwidth_hz
        inside = band is not None and band > 0.0 and low * (1 - tol) <= band <= high * (1 + tol)
        if band is not None and not inside:
            wrong.append(
                f"radar.bandwidth_hz: the radar says its digitised band is {band!r} Hz, "
                f"outside {low!r} .. {high!r} Hz that radar.receive, radar.bandwidth_hz and "
                "radar.sample_rate_hz allow"
            )
        for name in ("rf_reference_hz", "sample_rate_hz"):
            got = getattr(ctx, name)
            want = getattr(self.expect, name)
            if got is not None and abs(got - want) > tol * abs(want):
                wrong.append(f"radar.{name}: configured {want!r} Hz, the radar says {got!r} Hz")
        sid, before = ctx.stream_id, self.mismatch.get(ctx.stream_id)
        if not wrong:
            if before is not None:
                del self.mismatch[sid]
                log.warning(
                    "radar context of stream 0x%08x agrees with the configuration again: "
                    "its pulses are focused again", sid,
                )  # fmt: skip
            return
        reason = "; ".join(wrong)
        if reason != before:
            self.mismatch[sid] = reason
            self.counters.context_changes += 1
            log.error(
                "radar context of stream 0x%08x disagrees with the configuration (%s): its "
                "pulses are recorded flagged CONTEXT_MISMATCH and not focused until a "
                "context packet agrees again", sid, reason,
            )  # fmt: skip


class _Gathered:
    """The metadata of a batch's pulses as they are decoded, in row order: runs decoded
    together (arrays) and single packets (objects, made arrays once per stretch of them)."""

    def __init__(self, n_samples: int) -> None:
        self.n_samples = n_samples
        self.rows = 0
        """Rows written so far (the next pulse's row)."""
        self._parts: list[EchoPackets] = []
        self._singles: list[EchoPacket] = []

    def add(self, packet: EchoPacket | None) -> None:
        """A packet decoded on its own (None: nothing written)."""
        if packet is not None:
            self._singles.append(packet)
            self.rows += 1

    def add_run(self, run: EchoPackets) -> None:
        """Pulses decoded together, after the ones added so far."""
        self._flush()
        self._parts.append(run)
        self.rows += len(run)

    def packets(self) -> EchoPackets:
        """Every pulse added, in row order."""
        self._flush()
        return EchoPackets.concat(self._parts, self.n_samples)

    def _flush(self) -> None:
        if self._singles:
            self._parts.append(EchoPackets.of(self._singles, self.n_samples))
            self._singles = []


def _lost(count: Any, before: Any) -> Any:
    """Packets missing between packet counts ``before`` and ``count`` of one stream (ints, or
    arrays elementwise): the 4-bit count steps by one per packet."""
    return (count - before - 1) & 0xF


def _indicator(trailer: Any, bits: tuple[int, int], default: bool) -> Any:
    """A trailer indicator: its bit when its enable bit is set, else ``default`` (one trailer
    word as an int, or an array of them elementwise)."""
    enable, indicator = bits
    d = int(default)
    return d ^ ((trailer >> enable) & ((trailer >> indicator) ^ d) & 1) == 1


class VitaStreamFramer:
    """Cuts a byte stream (TCP, ``.vrt`` file) into packets and resynchronises after damage.

    Parameters
    ----------
    decoder : VitaDecoder
        Supplies the plausibility test for headers and counts skipped bytes.

    Notes
    -----
    A header is plausible only if it announces exactly the size this profile
    produces; otherwise the framer slides one byte. When the decoder refuses a
    candidate (``consume(..., ok=False)``) the framer also slides one byte, so
    a valid packet that starts inside a damaged one is still found. New bytes
    are fed only when no complete candidate is left, so the buffer never holds
    more than one maximal packet plus one read.
    """

    def __init__(self, decoder: VitaDecoder) -> None:
        self._decoder = decoder
        self._buf = bytearray()
        self._pos = 0

    def feed(self, data: bytes) -> None:
        """Append bytes read from the stream (release candidates first)."""
        if self._pos:
            del self._buf[: self._pos]
            self._pos = 0
        self._buf += data

    def next_packet(self) -> memoryview | None:
        """The next plausible packet (not consumed yet), or None if more bytes are needed."""
        buf, end = self._buf, len(self._buf)
        while end - self._pos >= 4:
            words = self._decoder.expected_words(_U32.unpack_from(buf, self._pos)[0])
            if words is None:
                self._pos += 1
                self._decoder.counters.skipped_bytes += 1
                continue
            if end - self._pos < 4 * words:
                return None
            return memoryview(buf)[self._pos : self._pos + 4 * words]
        return None

    def consume(self, packet: memoryview, ok: bool) -> None:
        """Release ``packet``; step past it if it decoded, else one byte further."""
        n = len(packet)
        packet.release()
        if ok:
            self._pos += n
        else:
            self._pos += 1
            self._decoder.counters.skipped_bytes += 1

    @property
    def pending_bytes(self) -> int:
        """Bytes buffered and not yet consumed."""
        return len(self._buf) - self._pos
