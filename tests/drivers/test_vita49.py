"""VITA 49.2 radar packets: round trips through UDP, TCP and .vrt files, and damage."""

from __future__ import annotations

import select
import socket
import struct
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sarmoco.drivers.radar import RadarFileSource, RadarTcpSource, RadarUdpSource
from sarmoco.drivers.samples import EchoPacket
from sarmoco.drivers.vita49 import (
    BATCH_MIN_PACKETS,
    ContextExpectation,
    VitaDecoder,
    encode_context_packet,
    encode_signal_packet,
)

N = 64
T0 = 1_400_000_000_000_000_000  # GPS ns, 2024
BATCH = BATCH_MIN_PACKETS
"""Pulses between context packets: batched decoding takes its fast path through them."""


def pulses(n_pulses: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    re = rng.integers(-30000, 30000, (n_pulses, N))
    im = rng.integers(-30000, 30000, (n_pulses, N))
    return (re + 1j * im).astype(np.complex64)


def times(n_pulses: int) -> list[int]:
    # irregular PRI with sub-µs parts
    return [T0 + k * 1_000_037 + (k * 7919) % 1000 for k in range(n_pulses)]


def packets(iq: np.ndarray, fmt: str = "int16", base: str = "gps", sid: int = 3) -> list[bytes]:
    return [
        encode_signal_packet(sid, t, k, iq[k], fmt, time_base=base)  # type: ignore[arg-type]
        for k, t in enumerate(times(len(iq)))
    ]


@pytest.mark.parametrize(("fmt", "base"), [("int16", "gps"), ("float32", "utc")])
def test_udp_round_trip(fmt: str, base: str) -> None:
    iq = pulses(40)
    dec = VitaDecoder(N, fmt, leap_s=18)  # type: ignore[arg-type]
    with RadarUdpSource("127.0.0.1", 0, dec) as src:
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx.sendto(
            encode_context_packet(
                3, T0, 0, bandwidth_hz=1.5e8, rf_reference_hz=9.6e9, sample_rate_hz=1.8e8
            ),
            src.address,
        )
        for p in packets(iq, fmt, base):
            tx.sendto(p, src.address)
        tx.close()
        out = np.zeros((64, N), np.complex64)
        got: list[EchoPacket] = []
        while len(got) < 40:
            batch = src.read_into(out[len(got) :], timeout_s=1.0)
            assert batch, "timed out"
            got += batch
    np.testing.assert_array_equal(out[:40], iq)
    assert [g.t_gps_ns for g in got] == times(40)
    assert all(g.stream_id == 3 and g.valid_data and g.lost_before == 0 for g in got)
    assert dec.context[3].sample_rate_hz == 1.8e8
    assert dec.counters.frames == 41 and dec.counters.gaps == 0


def test_datagrams_the_kernel_drops_are_counted(caplog: pytest.LogCaptureFixture) -> None:
    """A burst larger than the socket's receive buffer, sent while nobody reads: every
    datagram not received was dropped by the kernel, and the source counts each one."""
    n = 400
    dec = VitaDecoder(N, leap_s=18)
    with RadarUdpSource("127.0.0.1", 0, dec, rcvbuf_bytes=64 * 1024) as src:
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for p in packets(pulses(n)):
            tx.sendto(p, src.address)
        tx.close()
        out = np.zeros((n, N), np.complex64)
        got = 0
        while batch := src.read_into(out[got:], timeout_s=0.2):
            got += len(batch)
        assert 0 < got < n  # the burst overflowed the buffer
        src.count_kernel_drops()
        assert dec.counters.kernel_drops == n - got
    assert dec.counters.kernel_drops == n - got  # nothing more at close
    assert f"the kernel dropped {n - got} datagrams" in caplog.text


def test_int16_ring_keeps_raw_counts() -> None:
    iq = pulses(2)
    dec = VitaDecoder(N, "int16")
    out = np.zeros((2, N, 2), np.int16)
    for k, p in enumerate(packets(iq)):
        dec.decode_into(p, out[k])
    np.testing.assert_array_equal(out[..., 0], iq.real)
    np.testing.assert_array_equal(out[..., 1], iq.imag)


def test_packet_count_loss_and_trailer_flags() -> None:
    iq = pulses(20)
    pk = packets(iq)
    dec = VitaDecoder(N)
    row = np.zeros(N, np.complex64)
    got = [dec.decode_into(p, row) for i, p in enumerate(pk) if i not in (5, 6, 7)]
    assert [g.lost_before for g in got if g is not None].count(3) == 1
    assert dec.counters.gaps == 1 and dec.counters.drops == 3
    flagged = encode_signal_packet(
        1, T0, 0, iq[0], valid_data=False, sample_loss=True, over_range=True
    )
    e = dec.decode_into(flagged, row)
    assert e is not None and not e.valid_data and e.sample_loss and e.over_range


def test_context_change_flags_the_pulses_after_it_until_it_agrees_again(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A context packet that changes the sample rate mid-stream marks the stream: the pulses
    after it come back ``context_mismatch`` (counted, the change logged naming the key), in
    packet-by-packet and batched decoding alike, until a context packet agrees again."""
    want = ContextExpectation.for_receiver("matched", 1.5e8, 9.6e9, 1.8e8)
    iq = pulses(3 * BATCH)

    def context(rate_hz: float, count: int) -> bytes:
        return encode_context_packet(
            0, T0, count, bandwidth_hz=1.5e8, rf_reference_hz=9.6e9, sample_rate_hz=rate_hz
        )

    signal = packets(iq, sid=0)
    stream = [context(1.8e8, 0), *signal[:BATCH], context(2.0e8, 1), *signal[BATCH : 2 * BATCH]]
    stream += [context(1.8e8, 2), *signal[2 * BATCH :]]
    for batched in (False, True):
        dec = VitaDecoder(N, expect=want)
        rows = np.zeros((len(stream), N), np.complex64)
        if batched:
            stage = np.zeros((len(stream), dec.max_packet_bytes), np.uint8)
            for i, p in enumerate(stream):
                stage[i, : len(p)] = np.frombuffer(p, np.uint8)
            got = list(dec.decode_batch(stage, [len(p) for p in stream], rows))
        else:
            got = [e for p in stream if (e := dec.decode_into(p, rows[0])) is not None]
        mismatch = [e.context_mismatch for e in got]
        assert mismatch == [False] * BATCH + [True] * BATCH + [False] * BATCH
        assert dec.counters.context_changes == 1 and dec.counters.context_mismatch == BATCH
        assert dec.counters.frames == 3 * BATCH + 3 and dec.counters.parse_errors == 0
    assert "radar.sample_rate_hz: configured 180000000.0 Hz, the radar says 200000000.0 Hz" in (
        caplog.text
    )


@pytest.mark.parametrize(
    ("receive", "chirp_hz", "rate_hz", "reported_hz", "agrees"),
    [
        # pulsed LFM, complex sampling at 720 MHz of a 600 MHz chirp: any band that holds
        # the chirp and fits in the sample rate (the chirp's, the anti-alias filter's)
        ("matched", 600e6, 720e6, 600e6, True),
        ("matched", 600e6, 720e6, 700e6, True),
        ("matched", 600e6, 720e6, 720e6, True),
        ("matched", 600e6, 720e6, 500e6, False),  # the receiver cuts the chirp
        ("matched", 600e6, 720e6, 800e6, False),  # more than I/Q at 720 MHz can hold
        # dechirp of a 1.1 GHz chirp digitised at 40 MHz: the IF (beat) band, not the chirp's
        ("dechirp", 1.1e9, 40e6, 32e6, True),
        ("dechirp", 1.1e9, 40e6, 40e6, True),
        ("dechirp", 1.1e9, 40e6, 1.1e9, False),
        ("dechirp", 1.1e9, 40e6, 0.0, False),
    ],
)
def test_context_bandwidth_is_the_digitised_band(
    receive: str, chirp_hz: float, rate_hz: float, reported_hz: float, agrees: bool
) -> None:
    """VITA 49.2's context Bandwidth is the usable band of the signal digitised in the
    stream: a matched receiver's holds the chirp and fits in the sample rate, a dechirp
    receiver's is its beat band, up to the sample rate. The pulses after a context in those
    bounds are focused, the others flagged ``context_mismatch`` naming radar.bandwidth_hz."""
    want = ContextExpectation.for_receiver(receive, chirp_hz, 9.6e9, rate_hz)  # type: ignore[arg-type]
    dec = VitaDecoder(N, expect=want)
    context = encode_context_packet(
        3, T0, 0, bandwidth_hz=reported_hz, rf_reference_hz=9.6e9, sample_rate_hz=rate_hz
    )
    row = np.zeros(N, np.complex64)
    assert dec.decode_into(context, row) is None and dec.last_ok
    pulse = dec.decode_into(packets(pulses(1))[0], row)
    assert pulse is not None and pulse.context_mismatch is not agrees
    assert ("radar.bandwidth_hz" in dec.mismatch.get(3, "")) is not agrees


def test_context_longer_than_its_fields_is_damage() -> None:
    """A context packet whose CIF0 announces only fields the profile reads is exactly that
    long: one word more (a header in garbage whose size field would swallow the packets
    after it, as hypothesis found) is refused and counted, the exact one accepted."""
    dec = VitaDecoder(N)
    row = np.zeros(N, np.complex64)
    good = encode_context_packet(
        1, T0, 0, bandwidth_hz=1.5e8, rf_reference_hz=9.6e9, sample_rate_hz=1.8e8
    )
    assert dec.decode_into(good, row) is None and dec.last_ok
    words = struct.unpack_from(">I", good)[0] & 0xFFFF
    longer = struct.pack(">I", (struct.unpack_from(">I", good)[0] & ~0xFFFF) | (words + 1))
    longer += good[4:] + bytes(4)
    before = dec.counters.parse_errors
    assert dec.decode_into(longer, row) is None and not dec.last_ok
    assert dec.counters.parse_errors == before + 1


def test_tcp_stream_with_garbage_resyncs() -> None:
    iq = pulses(30, seed=1)
    pk = packets(iq)
    stream = b"\x00\x01garbage" + b"".join(pk[:10]) + b"\xff" * 37 + b"".join(pk[10:])
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def serve() -> None:
        conn, _ = server.accept()
        for i in range(0, len(stream), 1000):  # torn across reads
            conn.sendall(stream[i : i + 1000])
        conn.close()

    th = threading.Thread(target=serve)
    th.start()
    out = np.zeros((30, N), np.complex64)
    got: list[EchoPacket] = []
    with RadarTcpSource("127.0.0.1", port, VitaDecoder(N)) as src:
        while not src.eof and len(got) < 30:
            got += src.read_into(out[len(got) :], timeout_s=2.0)
        skipped = src.decoder.counters.skipped_bytes
    th.join()
    server.close()
    np.testing.assert_array_equal(out, iq)
    assert len(got) == 30 and skipped == 9 + 37


def test_vrt_file_round_trip(tmp_path: Path) -> None:
    iq = pulses(25, seed=2)
    path = tmp_path / "echo.vrt"
    path.write_bytes(b"".join(packets(iq)))
    out = np.zeros((8, N), np.complex64)
    rows = []
    with RadarFileSource(path, VitaDecoder(N)) as src:
        src.chunk_bytes = 777
        while not src.eof:
            got = src.read_into(out, 0.0)
            rows.append(out[: len(got)].copy())
    np.testing.assert_array_equal(np.concatenate(rows), iq)


# --- robustness ------------------------------------------------------------------------

_IQ = pulses(6, seed=3)
_PK = packets(_IQ)


_DATAGRAMS = st.one_of(
    st.binary(max_size=2000),
    st.tuples(st.sampled_from(_PK), st.integers(0, len(_PK[0]) - 1), st.integers(0, 255)).map(
        lambda t: t[0][: t[1]] + bytes([t[2]]) + t[0][t[1] + 1 :]
    ),
)
"""Random bytes, and good packets with one byte replaced (in the header or the payload)."""


@settings(max_examples=400, deadline=None)
@given(_DATAGRAMS)
def test_every_datagram_is_decoded_or_counted_bad(data: bytes) -> None:
    """No datagram raises: each is refused (None, one parse error, the row untouched) or
    decoded (one frame; a signal packet fills the row), and its bytes are counted."""
    dec = VitaDecoder(N)
    row = np.full(N, 7 + 7j, np.complex64)
    got = dec.decode_into(data, row)
    c = dec.counters
    assert c.bytes == len(data)
    if dec.last_ok:
        assert (c.frames, c.parse_errors) == (1, 0)
        assert (got is None) == bool(np.all(row == 7 + 7j))
    else:
        assert got is None and (c.frames, c.parse_errors) == (0, 1)
        assert np.all(row == 7 + 7j)


@settings(max_examples=400, deadline=None)
@given(
    idx=st.integers(0, 5),
    flips=st.lists(st.tuples(st.integers(0, len(_PK[0]) - 1), st.integers(0, 7)), max_size=4),
    cut=st.integers(0, len(_PK[0])),
    size_word=st.integers(0, 0xFFFF),
)
def test_damaged_stream_recovers_intact_packets(
    idx: int, flips: list[tuple[int, int]], cut: int, size_word: int
) -> None:
    damaged = bytearray(_PK[idx])
    for byte, bit in flips:
        damaged[byte] ^= 1 << bit
    if size_word % 3 == 0:  # absurd length field
        damaged[2:4] = size_word.to_bytes(2, "big")
    stream = b"".join(_PK[:idx]) + bytes(damaged[:cut]) + b"".join(_PK[idx + 1 :])
    dec = VitaDecoder(N)
    out = np.zeros((8, N), np.complex64)
    from sarmoco.drivers.vita49 import VitaStreamFramer

    framer = VitaStreamFramer(dec)
    framer.feed(stream)
    got: list[EchoPacket] = []
    while (p := framer.next_packet()) is not None:
        e = dec.decode_into(p, out[len(got)] if len(got) < 8 else out[7])
        framer.consume(p, dec.last_ok)
        if e is not None:
            got.append(e)
        assert framer.pending_bytes <= len(stream)
    seen = {g.t_gps_ns for g in got}
    ts = times(6)
    # every intact packet before the damage, and every one after the next, is recovered
    for k in range(6):
        if k < idx or k > idx + 1:
            assert ts[k] in seen


# --- batched UDP decoding equals packet-by-packet ----------------------------------------


def _one_by_one(
    datagrams: list[bytes], fmt: str = "int16", int16_ring: bool = False
) -> tuple[list[EchoPacket], np.ndarray, dict[str, int]]:
    dec = VitaDecoder(N, fmt, leap_s=18)  # type: ignore[arg-type]
    out = (
        np.zeros((len(datagrams), N, 2), np.int16)
        if int16_ring
        else np.zeros((len(datagrams), N), np.complex64)
    )
    got: list[EchoPacket] = []
    for d in datagrams:
        if (e := dec.decode_into(d, out[len(got)])) is not None:
            got.append(e)
    return got, out[: len(got)], dec.counters.snapshot()


def _mixed_datagrams(fmt: str = "int16") -> list[bytes]:
    iq = pulses(12, seed=5)
    ts = times(12)
    ctx = encode_context_packet(
        2, T0, 0, bandwidth_hz=1.5e8, rf_reference_hz=9.6e9, sample_rate_hz=1.8e8
    )
    out: list[bytes] = []
    for k in range(12):
        for sid in (1, 2, 7):  # three receive channels, interleaved
            if (sid, k) in ((2, 4), (2, 5), (7, 9)):
                continue  # lost on the link
            base = "utc" if k % 3 == 0 else "gps"
            out.append(encode_signal_packet(
                sid, ts[k] + sid, k, iq[k], fmt, time_base=base,  # type: ignore[arg-type]
                valid_data=k != 6, sample_loss=k == 7, over_range=sid == 7,
            ))  # fmt: skip
        if k == 3:
            out += [ctx, b"garbage!", out[-1][:-4]]  # context, junk, a torn packet
        if k == 8:
            bad_ps = bytearray(out[-1])
            bad_ps[20:28] = (10**12).to_bytes(8, "big")  # fraction of a second >= 1 s
            ignored = bytearray(out[-2])
            ignored[0] |= 0x03  # header bits 25/24, which the profile ignores
            out += [bytes(bad_ps), bytes(ignored)]
    return out


@pytest.mark.parametrize(("fmt", "int16_ring"), [("int16", False), ("float32", False),
                                                  ("int16", True)])  # fmt: skip
def test_udp_batches_equal_packet_by_packet(fmt: str, int16_ring: bool) -> None:
    datagrams = _mixed_datagrams(fmt)
    want, rows, counters = _one_by_one(datagrams, fmt, int16_ring)
    dec = VitaDecoder(N, fmt, leap_s=18)  # type: ignore[arg-type]
    with RadarUdpSource("127.0.0.1", 0, dec) as src:
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for d in datagrams:
            tx.sendto(d, src.address)
        tx.close()
        out = np.zeros_like(rows, shape=(len(datagrams), *rows.shape[1:]))
        got: list[EchoPacket] = []
        while len(got) < len(want):
            batch = src.read_into(out[len(got) :], timeout_s=1.0)
            assert batch, "timed out"
            got += batch
    assert got == want
    np.testing.assert_array_equal(out[: len(got)], rows)
    assert dec.counters.snapshot() == counters
    assert counters["gaps"] == 3 and counters["parse_errors"] == 3  # (the mix is as meant)


@settings(max_examples=200, deadline=None)
@given(
    picks=st.lists(st.integers(0, 40), min_size=32, max_size=60),  # batches >= BATCH_MIN_PACKETS
    flips=st.lists(st.tuples(st.integers(0, 60), st.integers(0, 290), st.integers(0, 7))),
)
def test_batch_decoder_equals_packet_decoder(
    picks: list[int], flips: list[tuple[int, int, int]]
) -> None:
    pool = _mixed_datagrams()
    datagrams = [bytearray(pool[i % len(pool)]) for i in picks]
    for which, byte, bit in flips:
        if which < len(datagrams) and byte < len(datagrams[which]):
            datagrams[which][byte] ^= 1 << bit
    want, rows, counters = _one_by_one([bytes(d) for d in datagrams])
    dec = VitaDecoder(N, leap_s=18)
    stage = np.zeros((len(datagrams), dec.max_packet_bytes + 4), np.uint8)
    for i, d in enumerate(datagrams):
        stage[i, : len(d)] = np.frombuffer(bytes(d), np.uint8)
    out = np.zeros((len(datagrams), N), np.complex64)
    got = list(dec.decode_batch(stage, [len(d) for d in datagrams], out))
    assert got == want
    np.testing.assert_array_equal(out[: len(got)], rows)
    assert dec.counters.snapshot() == counters


@pytest.mark.parametrize("batched", [False, True], ids=["decode_into", "decode_batch"])
def test_timestamp_kinds_outside_the_profile_are_rejected(batched: bool) -> None:
    """TSI 0 (none) or 3 (other), or a fraction that is not real-time picoseconds: the
    header checks both decode paths share refuse the packet, and only it."""
    iq = pulses(40, seed=4)
    datagrams = [bytearray(p) for p in packets(iq)]
    bad = {5: (0, 2), 9: (3, 2), 13: (2, 1), 17: (1, 3)}  # packet: (TSI, TSF)
    for k, (tsi, tsf) in bad.items():
        datagrams[k][1] = (datagrams[k][1] & 0x0F) | (tsi << 6) | (tsf << 4)
    dec = VitaDecoder(N)
    out = np.zeros((len(datagrams), N), np.complex64)
    if batched:
        stage = np.zeros((len(datagrams), dec.max_packet_bytes + 4), np.uint8)
        for i, d in enumerate(datagrams):
            stage[i, : len(d)] = np.frombuffer(bytes(d), np.uint8)
        got = list(dec.decode_batch(stage, [len(d) for d in datagrams], out))
    else:
        got = [e for i, d in enumerate(datagrams) if (e := dec.decode_into(bytes(d), out[i]))]
    keep = [k for k in range(len(datagrams)) if k not in bad]
    assert [e.t_gps_ns for e in got] == [times(len(iq))[k] for k in keep]
    assert dec.counters.parse_errors == len(bad)


def _udp_pair() -> tuple[socket.socket, socket.socket]:
    """A bound non-blocking receiver on 127.0.0.1 and a sender."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    return rx, socket.socket(socket.AF_INET, socket.SOCK_DGRAM)


@pytest.mark.parametrize("batch_receive", [True, False], ids=["recvmmsg", "recv_into"])
def test_udp_batch_path_equals_one_packet_path_on_real_sockets(batch_receive: bool) -> None:
    """The same datagrams over UDP on 127.0.0.1 to the radar source (batches of datagrams per
    system call, decoded together into an int16 ring) and to a socket read one datagram per
    call and decoded one packet per call: byte-identical rows, identical metadata and
    identical counters. The mix spans several batches, with other streams' packets, context
    packets, junk, torn packets, timestamps out of range, lost packets, and datagrams longer
    than the largest packet (cut by the receive buffer)."""
    mixed = _mixed_datagrams()
    iq = pulses(200, seed=9)
    datagrams = [*packets(iq[:150], sid=1)]
    datagrams[10:10] = mixed  # a damaged stretch inside a long clean run
    datagrams[80:80] = [datagrams[79] + bytes(64), datagrams[81][:-4] + bytes(4000)]  # too long
    datagrams += [encode_signal_packet(1, T0 + k, 150 + k, iq[150 + k]) for k in range(50)]
    del datagrams[200:203]  # a gap in the counts
    one = VitaDecoder(N, leap_s=18)
    rx, tx = _udp_pair()
    buf = bytearray(one.max_packet_bytes + 4)  # what the source receives into
    want_rows = np.zeros((len(datagrams), N, 2), np.int16)
    want: list[EchoPacket] = []
    dec = VitaDecoder(N, leap_s=18)
    with RadarUdpSource("127.0.0.1", 0, dec, batch_receive=batch_receive) as src:
        assert src.receiver.batched == batch_receive
        for d in datagrams:
            tx.sendto(d, src.address)
            tx.sendto(d, rx.getsockname())
        for _ in datagrams:
            n = rx.recv_into(buf) if select.select([rx], [], [], 1.0)[0] else 0
            assert n, "timed out"
            if (e := one.decode_into(memoryview(buf)[:n], want_rows[len(want)])) is not None:
                want.append(e)
        rows = np.zeros_like(want_rows)
        got: list[EchoPacket] = []
        while len(got) < len(want):
            batch = src.read_into(rows[len(got) :], timeout_s=1.0)
            assert len(batch), "timed out"
            got += batch
    rx.close()
    tx.close()
    assert got == want
    assert rows.tobytes() == want_rows.tobytes()
    assert dec.counters.snapshot() == one.counters.snapshot()
    c = one.counters
    assert (c.frames, c.parse_errors, c.gaps) == (len(want) + 1, 5, 6)  # (the mix is as meant)


@pytest.mark.parametrize(("configured", "decoded"), [(None, 0xC0FFEE01), (7, 7)])
def test_stream_selection_first_seen_or_configured(configured: int | None, decoded: int) -> None:
    """Unset, the first signal stream seen is decoded (a context packet of another stream
    before it does not choose); set, only that stream, whatever arrives first. Other streams
    are counted in rejected and named in skipped_streams."""
    iq = pulses(3 * BATCH)
    order = [0xC0FFEE01, 7, 0x10]
    ctx = encode_context_packet(
        0x10, T0, 0, bandwidth_hz=1.5e8, rf_reference_hz=9.6e9, sample_rate_hz=1.8e8
    )
    raw = [ctx]
    raw += [
        encode_signal_packet(order[k % 3], t, k // 3, iq[k], "int16")
        for k, t in enumerate(times(len(iq)))
    ]
    dec = VitaDecoder(N, "int16", stream_id=configured, first_stream=True)
    stage = np.zeros((len(raw), max(map(len, raw))), np.uint8)
    for i, p in enumerate(raw):
        stage[i, : len(p)] = np.frombuffer(p, np.uint8)
    out = np.zeros((len(raw), N), np.complex64)
    got = dec.decode_batch(stage, [len(p) for p in raw], out)
    mine = [k for k in range(len(iq)) if order[k % 3] == decoded]
    assert [g.stream_id for g in got] == [decoded] * len(mine)
    np.testing.assert_array_equal(out[: len(mine)], iq[mine])
    assert dec.stream_id == decoded and dec.skipped_streams == set(order) - {decoded}
    assert dec.counters.rejected == len(iq) - len(mine)
