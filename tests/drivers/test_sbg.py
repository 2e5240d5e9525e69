"""SBG sbgECom: CRC, round trips through a pseudo-terminal and a file, damage recovery."""

from __future__ import annotations

import math
import os
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sarmoco.drivers import sbg_codec as codec
from sarmoco.drivers.attitude import euler_to_quat
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.drivers.samples import AttitudeSample, EventSample, Validity, VelocitySample
from sarmoco.drivers.sbg import SbgDecoder, SbgFileSource, SbgSerialSource

LEAP = 18
G0 = 1_400_000_000_123_456_000  # GPS ns at device time D0
D0_US = 4_294_000_000  # device µs: wraps 2^32 during the run
SKEW = 2e-6  # device clock runs slow by 2 ppm
OK_STATUS = 4 | codec.SOL_ATTITUDE_VALID | codec.SOL_HEADING_VALID | codec.SOL_VELOCITY_VALID


def truth_gps(dev_us: int, skew: float = SKEW) -> int:
    return G0 + round((dev_us - D0_US) * 1000 * (1 + skew))


def utc_msg(dev_us: int, skew: float = SKEW) -> codec.UtcTime:
    gps = truth_gps(dev_us, skew)
    unix_ns = gps_ns_to_unix_ns(gps, LEAP)
    tm = time.gmtime(unix_ns // 1_000_000_000)
    tow_ms = (gps // 1_000_000) % (604_800 * 1000)
    status = (codec.CLOCK_VALID << 1) | (codec.UTC_INITIALIZED << 6) | codec.UTC_ACCURATE
    return codec.UtcTime(
        dev_us, status, tm.tm_year, tm.tm_mon, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
        unix_ns % 1_000_000_000, tow_ms,
    )  # fmt: skip


Truth = list[tuple[str, int, tuple[float, ...]]]


def scenario(n: int = 300, skew: float = SKEW, utc_every: int = 20) -> tuple[bytes, Truth]:
    """100 Hz EKF_NAV + EKF_QUAT/EULER, UTC_TIME every ``utc_every`` logs, an event every 0.5 s."""
    frames: list[bytes] = []
    truth: Truth = []
    for k in range(n):
        dev = (D0_US + k * 10_000) & 0xFFFFFFFF
        dev_ext = D0_US + k * 10_000
        if k % utc_every == 0:
            frames.append(codec.encode_message(utc_msg(dev_ext, skew)))
        vel = (30.0 + 0.01 * k, -2.0 + 0.001 * k, 0.5 * math.sin(k / 10))
        frames.append(
            codec.encode_message(
                codec.EkfNav(
                    dev, vel, (0.05, 0.05, 0.1), (43.6, 1.44, 150.0 + k), 48.0, (1, 1, 2), OK_STATUS
                )
            )
        )
        eul = (0.02 * math.sin(k / 7), 0.05, 1.0 + 0.001 * k)
        if k % 2:
            frames.append(codec.encode_message(codec.EkfEuler(dev, eul, (0.01,) * 3, OK_STATUS)))
        else:
            q = euler_to_quat(*eul)
            frames.append(codec.encode_message(codec.EkfQuat(dev, q, (0.01,) * 3, OK_STATUS)))
        truth.append(("vel", truth_gps(dev_ext, skew), vel))
        truth.append(("att", truth_gps(dev_ext, skew), euler_to_quat(*eul)))
        if k % 50 == 25:
            ev = codec.Event(dev, 0b11, (1234, 0, 0, 0))
            frames.append(codec.encode_message(ev))
            truth.append(("ev", truth_gps(dev_ext, skew), ()))
            truth.append(("ev", truth_gps(dev_ext + 1234, skew), ()))
    return b"".join(frames), truth


def check(samples: list[Any], truth: Truth) -> None:
    vel = [s for s in samples if isinstance(s, VelocitySample)]
    att = [s for s in samples if isinstance(s, AttitudeSample)]
    ev = [s for s in samples if isinstance(s, EventSample)]
    tv = [t for t in truth if t[0] == "vel"]
    ta = [t for t in truth if t[0] == "att"]
    te = [t for t in truth if t[0] == "ev"]
    assert (len(vel), len(att), len(ev)) == (len(tv), len(ta), len(te))
    for sv, (_, t, v) in zip(vel, tv, strict=True):
        assert abs(sv.t_gps_ns - t) <= 1000
        assert sv.vel_ned == pytest.approx(v, abs=1e-5)
        assert sv.valid & Validity.VELOCITY and sv.valid & Validity.TIME
    for s, (_, t, q) in zip(att, ta, strict=True):
        assert abs(s.t_gps_ns - t) <= 1000
        sign = 1 if s.quat[0] * q[0] >= 0 else -1
        assert [sign * c for c in s.quat] == pytest.approx(q, abs=1e-6)
    for se, (_, t, _) in zip(ev, te, strict=True):
        assert abs(se.t_gps_ns - t) <= 1000 and se.channel == "A"


def test_crc_kermit_check_value() -> None:
    assert codec.crc16_kermit(b"123456789") == 0x2189


def test_round_trip_through_pty() -> None:
    stream, truth = scenario()
    master, slave = os.openpty()
    src = SbgSerialSource(os.ttyname(slave), 921600, leap_s=LEAP)

    def write() -> None:
        for i in range(0, len(stream), 997):
            os.write(master, stream[i : i + 997])

    th = threading.Thread(target=write)
    th.start()
    samples: list[Any] = []
    deadline = time.monotonic() + 20
    while len(samples) < len(truth) + 15 and time.monotonic() < deadline:
        samples += src.poll(0.05)
    th.join()
    src.close()
    os.close(master)
    os.close(slave)
    check([s for s in samples if not type(s).__name__ == "TimeSample"], truth)
    assert src.counters.crc_errors == 0 and src.counters.frames > 600


@pytest.mark.parametrize("utc_every", [1, 40, 100])  # UTC_TIME at 100, 2.5 and 1 Hz
def test_fast_drift_mapped_from_the_first_sample(tmp_path: Path, utc_every: int) -> None:
    """40 ppm: the first logs were offset-only mapped, up to 16 µs off at 0.4 s."""
    stream, truth = scenario(150, skew=40e-6, utc_every=utc_every)
    path = tmp_path / "drift.bin"
    path.write_bytes(stream)
    with SbgFileSource(path, leap_s=LEAP) as src:
        samples = list(src.samples())
    check([s for s in samples if not type(s).__name__ == "TimeSample"], truth)


def test_file_with_garbage_and_leap_from_tow(tmp_path: Path) -> None:
    stream, truth = scenario()
    cut = len(stream) // 3
    damaged = b"\x5a\xff\xff" + stream[:cut] + b"\xff\x5a\x08\x00\xff\xff" + stream[cut:]
    path = tmp_path / "sbg.bin"
    path.write_bytes(damaged)
    with SbgFileSource(path, leap_s=17, chunk_bytes=501) as src:  # wrong leap: TOW corrects
        samples = list(src.samples())
    check([s for s in samples if not type(s).__name__ == "TimeSample"], truth)
    assert src.counters.parse_errors >= 1


def test_logs_before_second_utc_wait_and_reboot_resets() -> None:
    dec = SbgDecoder(LEAP)
    d1 = 100_000_000
    nav = codec.EkfNav(d1, (1.0, 2.0, 3.0), (0,) * 3, (0,) * 3, 0.0, (0,) * 3, OK_STATUS)
    assert dec.feed(codec.encode_message(nav)) == []
    assert dec.feed(codec.encode_message(utc_msg(d1 + 1000))) == []  # offset only: wait
    out = dec.feed(codec.encode_message(utc_msg(d1 + 201_000)))
    assert [type(s).__name__ for s in out] == ["VelocitySample", "TimeSample", "TimeSample"]
    reboot = codec.EkfNav(5_000_000, (1.0, 2.0, 3.0), (0,) * 3, (0,) * 3, 0.0, (0,) * 3, 0)
    assert dec.feed(codec.encode_message(reboot)) == [] and dec.counters.gaps == 1


# --- robustness ------------------------------------------------------------------------

_STREAM, _TRUTH = scenario(40)


def _frames_of(stream: bytes) -> list[bytes]:
    sn, _ = codec.new_sniffer("t")
    return [codec.encode_frame(f.msg_id, f.msg_class, f.payload) for f in sn.feed(stream)]


_ALL = _frames_of(_STREAM)


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=3000))
def test_random_bytes_never_raise(data: bytes) -> None:
    dec = SbgDecoder(LEAP)
    dec.feed(data)
    dec.feed(b"", final=True)
    assert len(dec.sniffer._buf) <= codec.MAX_FRAME


@settings(max_examples=500, deadline=None)
@given(
    idx=st.integers(0, len(_ALL) - 1),
    flips=st.lists(st.tuples(st.integers(0, 80), st.integers(0, 7)), max_size=3),
    cut=st.integers(0, 90),
    absurd=st.one_of(st.none(), st.integers(0, 0xFFFF)),
    chunk=st.integers(1, 400),
)
def test_damaged_frames_recovered_around(
    idx: int, flips: list[tuple[int, int]], cut: int, absurd: int | None, chunk: int
) -> None:
    bad = bytearray(_ALL[idx])
    for byte, bit in flips:
        if byte < len(bad):
            bad[byte] ^= 1 << bit
    if absurd is not None:
        bad[4:6] = absurd.to_bytes(2, "little")
    bad = bad[: min(cut, len(bad))] if cut < len(bad) else bad
    stream = b"".join(_ALL[:idx]) + bytes(bad) + b"".join(_ALL[idx + 1 :])
    sn, _ = codec.new_sniffer("t")
    got = []
    for i in range(0, len(stream), chunk):
        got += sn.feed(stream[i : i + chunk])
        assert len(sn._buf) <= codec.MAX_FRAME + chunk
    got += sn.feed(b"", final=True)
    encoded = [codec.encode_frame(f.msg_id, f.msg_class, f.payload) for f in got]
    intact = _ALL[:idx] + _ALL[idx + 1 :]
    assert [f for f in encoded if f in intact] == intact
