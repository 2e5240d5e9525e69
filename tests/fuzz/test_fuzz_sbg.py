"""Fuzzing the SBG decoders: sbgECom byte streams and SBG CAN frames (vendor DBC).

sbgECom streams start from frames of the project's encoder (every log the daemon reads,
with random fields: dates, times, NaN and infinite floats) and are then damaged; SBG CAN
frames start from the vendor's DBC (``../shared/data/can/sbgCan.dbc``, encoded by
cantools with random raw values over each signal's bit width), so the fuzzer reaches
the clock pairing and the EKF outputs, not only the length checks. Requirements: no
exception escapes a decoder, the sniffer's buffer stays within one frame plus the last
read, and no example allocates more than the cap (a frame claiming 64 KiB is never
waited for).
"""

from __future__ import annotations

from typing import Any

import cantools
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sarmoco.drivers import sbg_can as sc
from sarmoco.drivers import sbg_codec as codec
from sarmoco.drivers.sbg import SbgDecoder
from sarmoco.errors import ProtocolError
from tests.conftest import SHARED_DATA
from tests.fuzz.bounds import assert_named_error, bounded_allocation, stream_reads
from tests.fuzz.edits import edited

DBC = SHARED_DATA / "can" / "sbgCan.dbc"
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

u32 = st.integers(0, 2**32 - 1)
f32 = st.floats(width=32)
f64 = st.floats()


def _t(draw: Any) -> int:
    return int(draw(st.integers(0, 2**32 - 1)))


@st.composite
def message(draw: Any) -> codec.Message:
    """One sbgECom log the daemon decodes, every field random (NaN and inf included)."""
    kind = draw(st.sampled_from(["utc", "euler", "quat", "nav", "event"]))
    status = draw(u32)
    if kind == "utc":
        return codec.UtcTime(
            _t(draw), draw(st.integers(0, 0xFFFF)), draw(st.integers(1970, 2100)),
            *(draw(st.integers(-128, 127)) for _ in range(5)),
            draw(st.integers(-(2**31), 2**31 - 1)), draw(u32),
        )  # fmt: skip
    if kind == "euler":
        return codec.EkfEuler(_t(draw), tuple(draw(f32) for _ in range(3)),  # type: ignore[arg-type]
                              tuple(draw(f32) for _ in range(3)), status)  # type: ignore[arg-type]  # fmt: skip
    if kind == "quat":
        return codec.EkfQuat(_t(draw), tuple(draw(f32) for _ in range(4)),  # type: ignore[arg-type]
                             tuple(draw(f32) for _ in range(3)), status)  # type: ignore[arg-type]  # fmt: skip
    if kind == "nav":
        return codec.EkfNav(
            _t(draw), tuple(draw(f32) for _ in range(3)), tuple(draw(f32) for _ in range(3)),  # type: ignore[arg-type]
            tuple(draw(f64) for _ in range(3)), draw(f32), tuple(draw(f32) for _ in range(3)),  # type: ignore[arg-type]
            status,
        )  # fmt: skip
    return codec.Event(_t(draw), draw(st.integers(0, 0xFFFF)),
                       tuple(draw(st.integers(0, 0xFFFF)) for _ in range(4)))  # type: ignore[arg-type]  # fmt: skip


def _length(draw: Any, buf: bytearray) -> None:
    """Rewrite the length field (bytes 4..5, little endian), up to 64 KiB."""
    if len(buf) >= 6:
        buf[4:6] = draw(st.sampled_from([0, 1, 4086, 4087, 0xFFFF])).to_bytes(2, "little")


def damaged(frame: bytes) -> st.SearchStrategy[bytes]:
    """``frame`` with a few edits: bit flips, the length field rewritten (to 64 KiB), cut
    short, bytes inserted, or garbage appended."""
    return edited(frame, max_insert=6, max_append=40, format_edits={"length": _length})


frames = st.lists(
    st.one_of(
        message().map(codec.encode_message),
        message().map(codec.encode_message).flatmap(damaged),
        st.binary(max_size=64),
    ),
    max_size=12,
)


@FUZZ
@given(frames, st.lists(st.integers(1, 300), min_size=1, max_size=6))
def test_sbgecom_stream_never_raises(chunks_in: list[bytes], reads: list[int]) -> None:
    """Damaged frames, garbage and intact frames, fed in reads of random sizes, then three
    intact frames and the end of the file: the decoder delivers at least two of them (a
    damaged header whose length is plausible is waited for, then given up at the end)."""
    good = [codec.encode_message(codec.EkfEuler(k, (0.1, 0.2, 0.3), (0.0,) * 3, 0xF0))
            for k in range(1, 4)]  # fmt: skip
    stream = b"".join(chunks_in) + b"".join(good)
    dec = SbgDecoder()
    with bounded_allocation():
        for read, last in stream_reads(stream, reads):
            dec.feed(read, final=last)
            assert len(dec.sniffer._buf) <= codec.MAX_FRAME + len(read)
    assert dec.counters.frames >= 2


def test_a_frame_claiming_64k_is_not_waited_for() -> None:
    """Headers announcing 0xFFFF payload bytes (a known log, and a message of another
    class whose size the sniffer does not know) are refused at once, not buffered for:
    the frames after them come out before any more bytes arrive."""
    dec = SbgDecoder()
    known = bytearray(codec.encode_message(codec.Event(1, 0, (0, 0, 0, 0))))
    known[4:6] = b"\xff\xff"
    unknown = codec.SYNC + bytes([0x63, 0x01, 0xFF, 0xFF])
    good = b"".join(codec.encode_message(codec.Event(k, 0, (0, 0, 0, 0))) for k in (2, 3))
    with bounded_allocation(64 << 10):
        dec.feed(bytes(known) + good + unknown + good)
    assert dec.counters.frames == 4 and dec.counters.parse_errors >= 2


def _dbc() -> Any:
    if not DBC.is_file():
        pytest.fail(f"vendor DBC not found at {DBC}")
    return cantools.database.load_file(str(DBC), encoding="cp1252", strict=False)


_DB = _dbc()
_MESSAGES = [_DB.get_message_by_frame_id(cid) for cid in sorted(sc.LAYOUTS)]


@st.composite
def dbc_frame(draw: Any) -> tuple[int, bytes]:
    """A frame of the SBG set encoded by cantools from random raw values over each
    signal's bit width (every raw value the DBC can carry)."""
    msg = draw(st.sampled_from(_MESSAGES))
    values = {}
    for sig in msg.signals:
        lo, hi = (-(2 ** (sig.length - 1)), 2 ** (sig.length - 1) - 1) if sig.is_signed \
            else (0, 2**sig.length - 1)  # fmt: skip
        values[sig.name] = draw(st.integers(lo, hi))
    data = msg.encode(values, scaling=False, strict=False)
    return msg.frame_id, bytes(data)


@st.composite
def damaged_can(draw: Any, frame: tuple[int, bytes]) -> tuple[int, bytes]:
    """A frame with its data cut, lengthened past 8 bytes, bit-flipped or its ID changed."""
    cid, data = frame
    buf = bytearray(data)
    op = draw(st.sampled_from(["flip", "cut", "long", "id"]))
    if op == "flip" and buf:
        buf[draw(st.integers(0, len(buf) - 1))] ^= 1 << draw(st.integers(0, 7))
    elif op == "cut":
        del buf[draw(st.integers(0, len(buf))) :]
    elif op == "long":
        buf += draw(st.binary(min_size=1, max_size=8))
    else:
        cid = draw(st.sampled_from([*sc.LAYOUTS, 0, 0x7FF, 0x1FFFFFFF]))
    return cid, bytes(buf)


@FUZZ
@given(st.lists(st.one_of(dbc_frame(), dbc_frame().flatmap(damaged_can)), max_size=40))
def test_sbg_can_frames_from_the_vendor_dbc_never_raise(frames_in: list[tuple[int, bytes]]) -> None:
    """The stateful decoder takes anything; the frame codec either decodes a frame or
    refuses it with a ProtocolError that names the CAN ID."""
    dec = sc.SbgCanDecoder()
    with bounded_allocation():
        for cid, data in frames_in:
            dec.feed(cid, data)
            try:
                sc.decode(cid, data)
            except ProtocolError as exc:
                assert_named_error(exc, f"0x{cid:03x}")
    known = sum(cid in sc.LAYOUTS for cid, _ in frames_in)
    assert dec.counters.frames + dec.counters.parse_errors >= known  # a bad date is both
