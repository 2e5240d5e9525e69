"""Fuzzing the MAVLink path: frames through pymavlink's parser as the driver reads them.

Messages the decoder uses (and the link messages it answers) are encoded with random
field values over each field's type (NaN, infinities, any time stamp), then damaged, and
read through :class:`~sarmoco.drivers.mavlink.MavlinkSource` from a real ``.tlog`` file
and from a real UDP socket. Requirements: a live link never raises; a file raises only a
:class:`~sarmoco.errors.DriverError` naming the file; every sample that comes out has
finite values (a NaN velocity would reach the motion compensation); no example
allocates more than the cap.
"""

from __future__ import annotations

import math
import socket
import struct
import tempfile
import time
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sarmoco.drivers.mavlink import MavlinkSource, mavlink2
from sarmoco.drivers.samples import AttitudeSample, Sample, VelocitySample
from sarmoco.drivers.timesync import LinearClockFit
from sarmoco.errors import DriverError
from tests.fuzz.bounds import assert_named_error, bounded_allocation
from tests.fuzz.edits import edited

FUZZ = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
_MAV = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
MESSAGES = [
    mavlink2.MAVLink_local_position_ned_message,
    mavlink2.MAVLink_global_position_int_message,
    mavlink2.MAVLink_odometry_message,
    mavlink2.MAVLink_attitude_quaternion_message,
    mavlink2.MAVLink_attitude_message,
    mavlink2.MAVLink_system_time_message,
    mavlink2.MAVLink_ekf_status_report_message,
    mavlink2.MAVLink_timesync_message,
    mavlink2.MAVLink_heartbeat_message,
]
_SPECIAL_INTS = (0, 1, 8, 12, 1000, 10**15, 2**31 - 1, 2**32 - 1)


def _scalar(ftype: str) -> st.SearchStrategy[Any]:
    if ftype == "float":
        return st.floats(width=32)
    if ftype == "double":
        return st.floats()
    bits = int(ftype.removeprefix("u").removeprefix("int").removesuffix("_t"))
    lo, hi = (
        (0, 2**bits - 1) if ftype.startswith("u") else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    )
    special = [v for v in _SPECIAL_INTS if lo <= v <= hi]
    return st.integers(lo, hi) | st.sampled_from(special)


@st.composite
def frame(draw: Any) -> bytes:
    """One MAVLink 2 frame of a message the driver reads, every field random."""
    cls = draw(st.sampled_from(MESSAGES))
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    args = []
    for name, ftype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        n = lengths[name]
        args.append([draw(_scalar(ftype)) for _ in range(n)] if n else draw(_scalar(ftype)))
    return bytes(cls(*args).pack(_MAV))


def damaged(data: bytes) -> st.SearchStrategy[bytes]:
    """``data`` with one to three bit flips, cuts or insertions."""
    return edited(data, count=(1, 3))


frames = st.lists(st.one_of(frame(), frame().flatmap(damaged), st.binary(max_size=40)),
                  max_size=12)  # fmt: skip


def _check_samples(samples: list[Sample]) -> None:
    for s in samples:
        assert -(2**63) <= s.t_gps_ns < 2**63, s  # fits the store's int64 columns
        if isinstance(s, VelocitySample):
            assert all(map(math.isfinite, s.vel_ned)), s
            assert s.pos_ned is None or all(map(math.isfinite, s.pos_ned)), s
        elif isinstance(s, AttitudeSample):
            assert all(map(math.isfinite, s.quat)), s


@FUZZ
@given(frames, st.booleans())
def test_tlog_file_of_random_and_damaged_frames(chunks: list[bytes], damage_file: bool) -> None:
    """A telemetry log (8-byte time stamp + frame per record), optionally damaged as a
    whole, replayed to its end: samples finite, only a DriverError naming the file."""
    log = b"".join(struct.pack(">Q", 1_700_000_000_000_000 + 20_000 * k) + c
                   for k, c in enumerate(chunks))  # fmt: skip
    if damage_file and log:
        log = log[: len(log) // 2] + b"\x00\xfd" + log[len(log) // 2 :]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.tlog"
        path.write_bytes(log)
        src = MavlinkSource(str(path))
        try:
            with bounded_allocation():
                for _ in range(len(chunks) + 2):
                    _check_samples(src.poll())
                    if src.eof:
                        break
            assert src.eof
        except DriverError as exc:
            assert_named_error(exc, str(path))
        finally:
            src.close()


_LIVE: list[MavlinkSource] = []


def _live() -> tuple[MavlinkSource, socket.socket]:
    """One UDP source for every example (a socket per example would exhaust the ports)."""
    if not _LIVE:
        _LIVE.append(MavlinkSource("udpin:127.0.0.1:0", host_clock_is_utc=False))
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect(_LIVE[0]._conn.port.getsockname())
    return _LIVE[0], tx


@FUZZ
@given(frames)
def test_udp_datagrams_of_random_and_damaged_frames(chunks: list[bytes]) -> None:
    """The same frames as datagrams to a live UDP link, then a marker frame: the source
    never raises, its samples are finite, and the marker comes through."""
    src, tx = _live()
    marker = mavlink2.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(_MAV)
    for c in chunks:
        tx.send(c)
    tx.send(bytes(300))  # a damaged header's announced length is skipped by pymavlink
    frames0 = src.counters.frames
    tx.send(marker)
    tx.close()
    deadline = time.monotonic() + 2.0
    with bounded_allocation():
        while src.counters.frames == frames0 and time.monotonic() < deadline:
            _check_samples(src.poll(0.01))
    assert src.counters.frames > frames0


def test_repeated_system_time_does_not_break_the_clock_fit() -> None:
    """Regression (found by the UDP fuzz): three SYSTEM_TIME pairs at one boot time (a
    repeated datagram) made the skew fit's least squares raise LinAlgError out of poll()."""
    fit = LinearClockFit(window=32, outlier_ns=50_000_000)
    for _ in range(3):
        fit.add(5_000_000, 1_400_000_000_000_000_000)
    assert fit.map(5_000_000) == 1_400_000_000_000_000_000


def test_non_finite_and_out_of_range_fields_are_parse_errors() -> None:
    """Regression (found by the fuzz): ATTITUDE with an infinite angle raised ValueError
    out of poll(); a NaN velocity came out as a sample; a SYSTEM_TIME of 2^64-1 µs gave
    GPS times past int64. Each is now a counted parse error, and the link carries on."""
    src = MavlinkSource("udpin:127.0.0.1:0", host_clock_is_utc=False)  # no fuzz leftovers
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect(src._conn.port.getsockname())
    inf, nan = float("inf"), float("nan")
    bad = [  # after the autopilot's HEARTBEAT: the link listens to the autopilot only
        mavlink2.MAVLink_heartbeat_message(
            mavlink2.MAV_TYPE_FIXED_WING, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3
        ),
        mavlink2.MAVLink_attitude_message(10, 0.0, inf, 0.0, 0, 0, 0),
        mavlink2.MAVLink_local_position_ned_message(10, 0, 0, 0, nan, 0, 0),
        mavlink2.MAVLink_system_time_message(2**64 - 1, 10),
    ]
    errors0, frames0 = src.counters.parse_errors, src.counters.frames
    for m in bad:
        tx.send(m.pack(_MAV))
    tx.close()
    deadline = time.monotonic() + 2.0
    while src.counters.frames < frames0 + 4 and time.monotonic() < deadline:
        assert src.poll(0.01) == []
    src.close()
    assert src.counters.parse_errors - errors0 == 3
