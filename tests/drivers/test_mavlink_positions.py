"""MAVLink positions on the Earth: the EKF origin, GLOBAL_POSITION_INT as local NED, and the
finer message of a quantity taking precedence (real pymavlink frames in a ``.tlog``)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sarmoco.drivers.mavlink import FINER_HOLD_MS, MavlinkSource, mavlink2
from sarmoco.drivers.samples import AttitudeSample, Sample, TangentFrame, VelocitySample
from sarmoco.geodesy import geodetic_to_ned, ned_to_geodetic

ORIGIN = (47.3769, 8.5417, 408.0)
"""The autopilot's EKF origin (exact in degE7 and mm)."""
UNIX0_US = 1_700_000_000_000_000
"""UNIX time of boot time 0, µs."""


class _Sink:
    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def write(self, buf: bytes) -> None:
        self.frames.append(bytes(buf))


def tlog(path: Path, send: Callable[[Any], None]) -> list[Sample]:
    """Write a ``.tlog`` of SYSTEM_TIME every 100 ms of boot time 0..3 s plus what ``send``
    sends, and read it back through :class:`MavlinkSource`."""
    sink = _Sink()
    mav = mavlink2.MAVLink(sink, srcSystem=1, srcComponent=1)
    for ms in range(0, 3000, 100):
        mav.system_time_send(UNIX0_US + ms * 1000, ms)
    send(mav)
    path.write_bytes(b"".join(struct.pack(">Q", UNIX0_US) + f for f in sink.frames))
    with MavlinkSource(str(path)) as src:
        return list(src.samples())


def _int(lla: np.ndarray) -> tuple[int, int, int]:
    return round(lla[0] * 1e7), round(lla[1] * 1e7), round(lla[2] * 1e3)


def _velocities(samples: list[Sample]) -> list[VelocitySample]:
    return [s for s in samples if isinstance(s, VelocitySample)]


def test_local_positions_get_the_ekf_origin_and_their_geodetic_position(tmp_path: Path) -> None:
    ned = np.array([[120.0, -340.0, -95.0], [125.0, -338.0, -95.5]])

    def send(mav: Any) -> None:
        mav.gps_global_origin_send(*_int(np.asarray(ORIGIN)), 0)
        for k, p in enumerate(ned):
            mav.local_position_ned_send(1000 + 20 * k, *p, 17.5, 1.0, 0.0)

    vel = _velocities(tlog(tmp_path / "o.tlog", send))
    assert [s.pos_frame for s in vel] == [
        TangentFrame(ORIGIN, "mavlink.GPS_GLOBAL_ORIGIN", stated=True)
    ] * 2
    lla = np.array([s.lat_lon_alt for s in vel])
    assert np.allclose(geodetic_to_ned(lla, ORIGIN), ned, atol=1e-5)  # float32 on the wire


def test_without_an_origin_local_positions_name_no_frame(tmp_path: Path) -> None:
    def send(mav: Any) -> None:
        mav.local_position_ned_send(1000, 1.0, 2.0, -3.0, 17.5, 1.0, 0.0)

    (s,) = _velocities(tlog(tmp_path / "n.tlog", send))
    assert s.pos_ned == pytest.approx((1.0, 2.0, -3.0)) and s.pos_frame is None
    assert s.lat_lon_alt is None


def test_global_positions_are_local_ned_about_the_first_then_the_stated_origin(
    tmp_path: Path,
) -> None:
    """ArduPilot's default stream alone: positions NED about the first fix (stated as such),
    then, once GPS_GLOBAL_ORIGIN arrives, about the EKF origin; cm quantisation only."""
    ned = np.array([[100.0, 200.0, -50.0], [110.0, 205.0, -50.2], [120.0, 210.0, -50.4]])
    lla = ned_to_geodetic(ned, ORIGIN)

    def send(mav: Any) -> None:
        for k in range(3):
            if k == 2:
                mav.gps_global_origin_send(*_int(np.asarray(ORIGIN)), 0)
            mav.global_position_int_send(1000 + 250 * k, *_int(lla[k]), 50_000, 1750, 100, 0, 0)

    vel = _velocities(tlog(tmp_path / "g.tlog", send))
    assert len(vel) == 3
    first = TangentFrame(tuple(vel[0].lat_lon_alt), "mavlink.GLOBAL_POSITION_INT")  # type: ignore[arg-type]
    assert vel[0].pos_frame == vel[1].pos_frame == first
    assert vel[0].pos_ned == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    p1, p2 = vel[1].pos_ned, vel[2].pos_ned
    assert p1 is not None and p2 is not None
    assert np.allclose(p1, ned[1] - ned[0], atol=0.02)
    assert vel[2].pos_frame == TangentFrame(ORIGIN, "mavlink.GPS_GLOBAL_ORIGIN", stated=True)
    assert np.allclose(p2, ned[2], atol=0.01)
    assert vel[0].vel_ned == pytest.approx((17.5, 1.0, 0.0))


def test_a_global_and_a_local_position_of_one_instant_give_the_ekf_origin(
    tmp_path: Path,
) -> None:
    """ArduPilot sends GLOBAL_POSITION_INT then LOCAL_POSITION_NED of the same boot time and
    GPS_GLOBAL_ORIGIN only when the origin is set: the pair gives the origin (within the
    1 cm of degE7), the finer LOCAL_POSITION_NED gives the samples."""
    ned = np.array([[2500.0, -1800.0, -120.0], [2500.35, -1799.9, -120.0]])
    lla = ned_to_geodetic(ned, ORIGIN)

    def send(mav: Any) -> None:
        for k in range(2):
            ms = 1000 + 20 * k
            mav.global_position_int_send(ms, *_int(lla[k]), 120_000, 1750, 500, 0, 0)
            mav.local_position_ned_send(ms, *ned[k], 17.5, 5.0, 0.0)

    vel = _velocities(tlog(tmp_path / "p.tlog", send))
    # the first GLOBAL_POSITION_INT precedes any LOCAL_POSITION_NED (the nav buffer keeps
    # one sample per instant); from then on LOCAL_POSITION_NED alone
    assert [s.source for s in vel] == [
        "mavlink.GLOBAL_POSITION_INT",
        "mavlink.LOCAL_POSITION_NED",
        "mavlink.LOCAL_POSITION_NED",
    ]
    frame = vel[2].pos_frame
    assert frame is not None and frame.source == "mavlink.GLOBAL_POSITION_INT - LOCAL_POSITION_NED"
    assert vel[1].pos_frame == frame
    assert np.linalg.norm(geodetic_to_ned(np.asarray(frame.lat_lon_alt), ORIGIN)) < 0.01
    assert np.linalg.norm(geodetic_to_ned(np.asarray(vel[2].lat_lon_alt), ORIGIN) - ned[1]) < 0.01


def test_the_coarser_message_gives_way_while_the_finer_one_arrives(tmp_path: Path) -> None:
    """ATTITUDE beside ATTITUDE_QUATERNION gives no sample; after FINER_HOLD_MS without a
    quaternion it does again."""
    late = 1000 + FINER_HOLD_MS + 100

    def send(mav: Any) -> None:
        mav.attitude_quaternion_send(1000, 1.0, 0.0, 0.0, 0.0, 0, 0, 0)
        mav.attitude_send(1000, 0.1, 0.0, 0.0, 0, 0, 0)
        mav.attitude_send(1500, 0.1, 0.0, 0.0, 0, 0, 0)
        mav.attitude_send(late, 0.1, 0.0, 0.0, 0, 0, 0)

    att = [s for s in tlog(tmp_path / "a.tlog", send) if isinstance(s, AttitudeSample)]
    assert [(s.source, s.device_time_ns // 10**6) for s in att] == [
        ("mavlink.ATTITUDE_QUATERNION", 1000),
        ("mavlink.ATTITUDE", late),
    ]
