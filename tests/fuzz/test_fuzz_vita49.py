"""Fuzzing the VITA 49.2 decoder: single packets, batches and the stream framer.

Mutations start from packets of the project's own encoder so that the fuzzer reaches the
payload, trailer and context paths, not only the first header check. Requirements: no
exception (a context packet that contradicts the configuration marks its stream, with a
reason naming the key), a rejected packet leaves
the destination row untouched, the batch path agrees with the packet-by-packet path on
any input, the framer's buffer stays bounded, and no example allocates more than
:data:`~tests.fuzz.bounds.ALLOC_CAP_BYTES` (a header's length field is never believed).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sarmoco.drivers.vita49 import (
    BATCH_MIN_PACKETS,
    ContextExpectation,
    VitaDecoder,
    VitaStreamFramer,
    encode_context_packet,
    encode_signal_packet,
)
from tests.fuzz.bounds import bounded_allocation, stream_reads
from tests.fuzz.edits import edited

FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])

payloads = st.sampled_from(["int16", "float32"])
time_bases = st.sampled_from(["gps", "utc"])


@st.composite
def signal_packet(draw: Any, n_samples: int, payload: str) -> bytes:
    """A valid signal packet of the profile, with random metadata and samples."""
    iq = np.array(draw(st.lists(st.integers(-32768, 32767), min_size=2 * n_samples,
                                max_size=2 * n_samples)), dtype=np.int16)  # fmt: skip
    return encode_signal_packet(
        draw(st.sampled_from([0, 0, 0, 1, 0xFFFFFFFF])),
        draw(st.integers(0, 2**62)),
        draw(st.integers(0, 15)),
        iq,
        payload,  # type: ignore[arg-type]
        time_base=draw(time_bases),
        valid_data=draw(st.booleans()),
        sample_loss=draw(st.booleans()),
        over_range=draw(st.booleans()),
    )


@st.composite
def context_packet(draw: Any) -> bytes:
    """A valid context packet with random frequencies."""
    hz = st.floats(-1e12, 1e12, allow_nan=False)
    return encode_context_packet(
        0, draw(st.integers(0, 2**62)), draw(st.integers(0, 15)), bandwidth_hz=draw(hz),
        rf_reference_hz=draw(hz), sample_rate_hz=draw(hz), time_base=draw(time_bases),
    )  # fmt: skip


def _word(draw: Any, buf: bytearray) -> None:
    """Replace one of the first eight 32-bit words (the header and its fields)."""
    if len(buf) >= 4:
        at = 4 * draw(st.integers(0, min(7, len(buf) // 4 - 1)))
        buf[at : at + 4] = draw(st.integers(0, 2**32 - 1)).to_bytes(4, "big")


def _size(draw: Any, buf: bytearray) -> None:
    """Rewrite the packet-size field (words, up to 0xFFFF)."""
    if len(buf) >= 4:
        size = draw(st.sampled_from([0, 1, 5, 0x7FFF, 0xFFFF, len(buf) // 4 + 1]))
        buf[2:4] = size.to_bytes(2, "big")


def _short(draw: Any, buf: bytearray) -> None:
    """Cut to whole words with the size field agreeing (headers more often than payloads)."""
    if len(buf) >= 4:
        most = max(len(buf) // 4, 1)
        words = draw(st.integers(1, min(8, most)) | st.integers(1, most))
        del buf[4 * words :]
        buf[2:4] = words.to_bytes(2, "big")


def mutated(packet: bytes) -> st.SearchStrategy[bytes]:
    """``packet`` with a few random edits: bit flips, a header word or length field
    rewritten (up to 0xFFFF words), cut short (with or without its size field agreeing),
    bytes inserted or appended."""
    edits = {"word": _word, "size": _size, "short": _short}
    return edited(packet, count=(0, 4), max_append=64, format_edits=edits)


@st.composite
def packet_set(draw: Any, min_size: int = 1, max_size: int = 6) -> tuple[int, str, list[bytes]]:
    """Decoder parameters and packets of that profile, some mutated, some random bytes."""
    n_samples, payload = draw(st.integers(1, 24)), draw(payloads)
    one = st.one_of(
        signal_packet(n_samples, payload),
        context_packet(),
        signal_packet(n_samples, payload).flatmap(mutated),
        context_packet().flatmap(mutated),
        st.binary(max_size=200),
    )
    return n_samples, payload, draw(st.lists(one, min_size=min_size, max_size=max_size))


@FUZZ
@given(packet_set())
def test_decode_into_never_raises_and_keeps_rejected_rows(
    case: tuple[int, str, list[bytes]],
) -> None:
    n_samples, payload, packets = case
    dec = VitaDecoder(n_samples, payload)  # type: ignore[arg-type]
    row = np.empty(n_samples, np.complex64)
    with bounded_allocation():
        for pkt in packets:
            row.fill(np.complex64(7 + 7j))
            got = dec.decode_into(pkt, row)
            if got is None:
                assert (row == np.complex64(7 + 7j)).all(), "a rejected packet wrote the row"
            else:
                assert got.n_samples == n_samples and 0 <= got.packet_count <= 15
                assert 0 <= got.lost_before <= 15
    c = dec.counters
    assert c.frames + c.parse_errors + c.rejected <= len(packets)


@FUZZ
@given(st.lists(st.one_of(context_packet(), context_packet().flatmap(mutated)), max_size=5))
def test_context_packets_against_configuration(packets: list[bytes]) -> None:
    """A context packet either agrees, is rejected (counted), or contradicts the
    configuration: then its stream is marked with a reason naming the radar key, counted,
    and nothing is raised."""
    expect = ContextExpectation.for_receiver("matched", 750e6, 15e9, 1e9)
    dec = VitaDecoder(8, expect=expect)
    row = np.empty(8, np.complex64)
    for pkt in packets:
        assert dec.decode_into(pkt, row) is None
        for reason in dec.mismatch.values():
            assert reason.startswith(("radar.bandwidth_hz", "radar.rf_reference_hz",
                                      "radar.sample_rate_hz")), reason  # fmt: skip
    assert dec.counters.context_changes >= len(dec.mismatch)


def test_a_header_claiming_64k_words_allocates_nothing() -> None:
    """The largest length a header can claim (0xFFFF words, 256 KiB) on a short packet:
    rejected by the length check, before any buffer is made."""
    dec = VitaDecoder(16)
    pkt = bytearray(encode_signal_packet(0, 10**18, 0, np.zeros(16, np.complex64)))
    pkt[2:4] = b"\xff\xff"
    framer = VitaStreamFramer(dec)
    with bounded_allocation(64 << 10):
        assert dec.decode_into(bytes(pkt), np.empty(16, np.complex64)) is None
        framer.feed(bytes(pkt) * 4)
        while (candidate := framer.next_packet()) is not None:
            framer.consume(
                candidate, dec.decode_into(candidate, np.empty(16, np.complex64)) is not None
            )
    assert dec.counters.frames == 0


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(packet_set(min_size=BATCH_MIN_PACKETS, max_size=BATCH_MIN_PACKETS + 8))
def test_batch_decode_equals_packet_by_packet(case: tuple[int, str, list[bytes]]) -> None:
    """The vectorised batch path gives what :meth:`VitaDecoder.decode_into` gives, packet by
    packet, on damaged batches too: the same pulses, rows, counters."""
    n_samples, payload, packets = case
    fast, slow = VitaDecoder(n_samples, payload), VitaDecoder(n_samples, payload)  # type: ignore[arg-type]
    width = fast.max_packet_bytes + 16
    stage = np.zeros((len(packets), width), np.uint8)
    lengths = []
    for i, pkt in enumerate(packets):
        pkt = pkt[:width]
        stage[i, : len(pkt)] = np.frombuffer(pkt, np.uint8)
        lengths.append(len(pkt))
    out_fast = np.full((len(packets), n_samples), 3 + 3j, np.complex64)
    out_slow = out_fast.copy()
    with bounded_allocation():
        got_fast = list(fast.decode_batch(stage, lengths, out_fast))
    got_slow = []
    for i, n in enumerate(lengths):
        pkt = slow.decode_into(bytes(stage[i, :n]), out_slow[len(got_slow)])
        if pkt is not None:
            got_slow.append(pkt)
    assert got_fast == got_slow
    np.testing.assert_array_equal(out_fast, out_slow)
    assert fast.counters.snapshot() == slow.counters.snapshot()


@FUZZ
@given(packet_set(max_size=8), st.lists(st.integers(1, 700), min_size=1, max_size=8))
def test_stream_framer_resynchronises_with_a_bounded_buffer(
    case: tuple[int, str, list[bytes]], chunks: list[int]
) -> None:
    """Damage and garbage followed by three clean packets and the stream going on: the
    framer never raises, its buffer never exceeds one maximal packet plus one read, and at
    least two of the three clean packets come out (one may be swallowed by a candidate that
    starts in the damage). The stream goes on for a maximal packet of zero bytes after them:
    a candidate header in the damage may announce more bytes than the clean packets hold
    (``40 00 00`` + the first clean byte is a 28-word context header), and only the bytes
    after it complete that candidate, so that it is refused and the framer resynchronises."""
    n_samples, payload, packets = case
    dec = VitaDecoder(n_samples, payload)  # type: ignore[arg-type]
    iq = np.arange(2 * n_samples, dtype=np.int16)  # small positive words: no fake headers
    clean = [encode_signal_packet(0, 10**18 + k, k, iq, payload) for k in range(3)]  # type: ignore[arg-type]
    stream = b"".join(packets) + b"".join(clean) + bytes(dec.max_packet_bytes)
    row = np.empty(n_samples, np.complex64)
    framer = VitaStreamFramer(dec)
    times = []
    with bounded_allocation():
        for read, _ in stream_reads(stream, chunks):
            framer.feed(read)
            while (pkt := framer.next_packet()) is not None:
                got = dec.decode_into(pkt, row)
                if got is not None:
                    times.append(got.t_gps_ns)
                framer.consume(pkt, dec.last_ok)
            assert framer.pending_bytes <= dec.max_packet_bytes + len(read)
    assert sum(t in times for t in (10**18, 10**18 + 1, 10**18 + 2)) >= 2


@pytest.mark.parametrize("payload", ["int16", "float32"])
def test_random_bytes_never_raise(payload: str) -> None:
    """Plain noise, a datagram at a time and as a stream (a fixed seed, 2000 datagrams)."""
    rng = np.random.default_rng(5)
    dec = VitaDecoder(8, payload)  # type: ignore[arg-type]
    framer = VitaStreamFramer(dec)
    row = np.empty(8, np.complex64)
    for _ in range(2000):
        blob = rng.bytes(int(rng.integers(0, 120)))
        dec.decode_into(blob, row)
        framer.feed(blob)
        while (pkt := framer.next_packet()) is not None:
            dec.decode_into(pkt, row)
            framer.consume(pkt, dec.last_ok)
    assert dec.counters.parse_errors > 1000
