"""SBG CAN: codec against the vendor DBC, round trips over slcan (pty), socketcand
(TCP loopback), virtual bus and log files, and damaged frames."""

from __future__ import annotations

import math
import os
import socket
import threading
import time
from pathlib import Path
from typing import Any

import can
import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sarmoco.drivers import sbg_can as sc
from sarmoco.drivers import sbg_codec
from sarmoco.drivers.attitude import euler_to_quat
from sarmoco.drivers.can_source import CanLogSource, CanSource
from sarmoco.drivers.clock import gps_ns_to_unix_ns
from sarmoco.drivers.samples import AttitudeSample, EventSample, Validity, VelocitySample
from sarmoco.drivers.sbg_can import SbgCanDecoder
from tests.conftest import SHARED_DATA

DBC = SHARED_DATA / "can" / "sbgCan.dbc"
LEAP = 18
G0 = 1_400_000_000_000_000_000  # GPS ns at D0 (whole ms)
D0_US = 50_000_000


def frames(n: int = 100) -> tuple[list[tuple[int, bytes]], list[tuple[str, int, tuple]]]:
    """50 Hz EKF outputs, UTC_0/UTC_1 at 5 Hz, one event; device clock = GPS (steered)."""
    out: list[tuple[int, bytes]] = []
    truth: list[tuple[str, int, tuple]] = []
    status = 4 | sbg_codec.SOL_ATTITUDE_VALID | sbg_codec.SOL_HEADING_VALID
    status |= sbg_codec.SOL_VELOCITY_VALID
    out.append(sc.encode(sc.ID_STATUS_03, status, 0))
    out.append(sc.encode(sc.ID_STATUS_01, D0_US, 0, sbg_codec.CLOCK_VALID << 1))
    for k in range(n):
        dev = D0_US + k * 20_000
        gps = G0 + (dev - D0_US) * 1000
        if k % 10 == 0:
            unix = gps_ns_to_unix_ns(gps, LEAP)
            tm = time.gmtime(unix // 10**9)
            us = (unix // 1000) % 1_000_000
            out.append(sc.encode_utc_1(tm.tm_year, tm.tm_mon, tm.tm_mday, tm.tm_hour, tm.tm_min,
                                       tm.tm_sec, us))  # fmt: skip
            out.append(sc.encode(sc.ID_UTC_0, dev, (gps // 10**6) % (604_800_000)))
        out.append(sc.encode(sc.ID_EKF_INFO, dev))
        vel = (25.0 + 0.01 * k, -3.0, 0.2 * math.sin(k / 5))
        rpy = (0.03 * math.sin(k / 9), -0.02, 2.0 + 0.002 * k)
        out.append(sc.encode_ekf_vel_ned(vel))
        if k % 2:
            out.append(sc.encode_ekf_euler(*rpy))
        else:
            out.append(sc.encode_ekf_quat(euler_to_quat(*rpy)))
        truth.append(("vel", gps, vel))
        truth.append(("att", gps, euler_to_quat(*rpy)))
        if k == 55:
            out.append(sc.encode(sc.ID_EVENT_INFO_A, dev + 123, 0b11))
            out.append(sc.encode(sc.ID_EVENT_TIME_A, 500, 0, 0, 0))
            truth.append(("ev", gps + 123_000, ()))
            truth.append(("ev", gps + 623_000, ()))
    return out, truth


def check(samples: list[Any], truth: list[Any]) -> None:
    vel = [s for s in samples if isinstance(s, VelocitySample)]
    att = [s for s in samples if isinstance(s, AttitudeSample)]
    ev = [s for s in samples if isinstance(s, EventSample)]
    tv, ta, te = ([t for t in truth if t[0] == k] for k in ("vel", "att", "ev"))
    assert (len(vel), len(att), len(ev)) == (len(tv), len(ta), len(te))
    for sv, (_, t, v) in zip(vel, tv, strict=True):
        assert abs(sv.t_gps_ns - t) <= 1000
        assert sv.vel_ned == pytest.approx(v, abs=0.006)
        assert sv.valid & Validity.VELOCITY and sv.valid & Validity.TIME
    for s, (_, t, q) in zip(att, ta, strict=True):
        assert abs(s.t_gps_ns - t) <= 1000
        assert s.quat == pytest.approx(q, abs=2e-4)
    for se, (_, t, _) in zip(ev, te, strict=True):
        assert abs(se.t_gps_ns - t) <= 1000


def test_layouts_match_vendor_dbc() -> None:
    db: Any = cantools.database.load_file(str(DBC), encoding="cp1252", strict=False)
    cases: dict[int, Any] = {
        sc.ID_EKF_VEL_NED: (sc.encode_ekf_vel_ned((12.34, -5.67, 0.89)),
                            {"VELOCITY_N": 12.34, "VELOCITY_E": -5.67, "VELOCITY_D": 0.89}),
        sc.ID_EKF_EULER: (sc.encode_ekf_euler(0.1234, -0.5, 2.5),
                          {"ROLL": 0.1234, "PITCH": -0.5, "YAW": 2.5}),
        sc.ID_EKF_QUAT: (sc.encode_ekf_quat((0.5, -0.5, 0.5, 0.5)),
                         {"Q0": 0.5, "Q1": -0.5, "Q2": 0.5, "Q3": 0.5}),
        sc.ID_EKF_INFO: (sc.encode(sc.ID_EKF_INFO, 123456789), {"TIME_STAMP": 123456789}),
        sc.ID_UTC_0: (sc.encode(sc.ID_UTC_0, 42, 345_678_900), {"TIME_STAMP": 42,
                                                                 "GPS_TOW": 345_678_900}),
        sc.ID_UTC_1: (sc.encode_utc_1(2024, 5, 17, 13, 45, 59, 987_600),
                      {"YEAR": 2024, "MONTH": 5, "DAY": 17, "HOUR": 13, "MIN": 45, "SEC": 59,
                       "MICRO_SEC": 987_600}),
        sc.ID_STATUS_01: (sc.encode(sc.ID_STATUS_01, 7, 8, 9),
                          {"TIME_STAMP": 7, "GENERAL": 8, "CLOCK": 9}),
        sc.ID_STATUS_03: (sc.encode(sc.ID_STATUS_03, 0xF4, 3), {"SOLUTION": 0xF4,
                                                                "HEAVE_STATUS": 3}),
        sc.ID_EVENT_INFO_A: (sc.encode(sc.ID_EVENT_INFO_A, 99, 6), {"TIME_STAMP": 99,
                                                                    "STATUS": 6}),
        sc.ID_EVENT_TIME_A: (sc.encode(sc.ID_EVENT_TIME_A, 1, 2, 3, 4),
                             {f"TIME_OFFSET_{i}": i + 1 for i in range(4)}),
    }  # fmt: skip
    for can_id, ((cid, data), want) in cases.items():
        assert cid == can_id
        msg = db.get_message_by_frame_id(can_id)
        got = msg.decode(data.ljust(msg.length, b"\0"), decode_choices=False)
        for name, value in want.items():
            assert got[name] == pytest.approx(value, abs=1e-4), (hex(can_id), name)
        # and the other way: the vendor's encoding decodes to the same raw fields
        theirs = msg.encode(got)
        assert sc.decode(can_id, theirs) == sc.decode(can_id, data.ljust(msg.length, b"\0"))


def test_virtual_bus_round_trip() -> None:
    fr, truth = frames()
    tx = can.Bus(interface="virtual", channel="sarmoco-test")
    src = CanSource.open("virtual", "sarmoco-test", leap_s=LEAP)
    for cid, data in fr:
        tx.send(can.Message(arbitration_id=cid, data=data, is_extended_id=False))
    samples = src.poll(0.5)
    tx.shutdown()
    src.close()
    check(samples, truth)


def test_slcan_adapter_on_pty() -> None:
    fr, truth = frames()
    master, slave = os.openpty()
    src = CanSource.open("slcan", os.ttyname(slave), leap_s=LEAP, sleep_after_open=0)
    lines = [f"t{cid:03X}{len(d)}{d.hex().upper()}\r".encode() for cid, d in fr]
    lines.insert(7, b"tZZZ8garbage\r")  # a line the adapter mangled

    def adapter() -> None:  # the simulated USB-CAN adapter: ASCII slcan lines
        for line in lines:
            os.write(master, line)

    th = threading.Thread(target=adapter)
    th.start()
    samples: list = []
    deadline = time.monotonic() + 20
    while len(samples) < len(truth) + 10 and time.monotonic() < deadline:
        samples += src.poll(0.05)
    th.join()
    src.close()
    os.close(master)
    os.close(slave)
    check([s for s in samples if type(s).__name__ != "TimeSample"], truth)
    assert src.counters.parse_errors >= 1


def test_socketcand_over_tcp_loopback() -> None:
    fr, truth = frames(60)
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def daemon() -> None:  # the socketcand side of the protocol
        conn, _ = server.accept()
        conn.sendall(b"< hi >")
        assert conn.recv(256).startswith(b"< open can0 >")
        conn.sendall(b"< ok >")
        assert conn.recv(256).startswith(b"< rawmode >")
        conn.sendall(b"< ok >")
        for k, (cid, d) in enumerate(fr):
            conn.sendall(f"< frame {cid:03X} {k}.000000 {d.hex().upper()} >".encode())
        time.sleep(0.5)
        conn.close()

    th = threading.Thread(target=daemon)
    th.start()
    src = CanSource.open("socketcand", "can0", leap_s=LEAP, host="127.0.0.1", port=port)
    samples: list = []
    deadline = time.monotonic() + 10
    while len(samples) < len(truth) + 6 and time.monotonic() < deadline:
        samples += src.poll(0.05)
    th.join()
    src.close()
    server.close()
    check([s for s in samples if type(s).__name__ != "TimeSample"], truth)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_log_replay(tmp_path: Path, suffix: str) -> None:
    fr, truth = frames()
    path = tmp_path / f"sbg{suffix}"
    with can.Logger(str(path)) as logger:
        for k, (cid, d) in enumerate(fr):
            logger(can.Message(timestamp=1e9 + k * 1e-3, arbitration_id=cid, data=d,
                               is_extended_id=False))  # fmt: skip
    with CanLogSource(path, leap_s=LEAP, frames_per_poll=37) as src:
        samples = list(src.samples())
    check([s for s in samples if type(s).__name__ != "TimeSample"], truth)


@settings(max_examples=600, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([*sorted(sc.LAYOUTS), 0x7FF]),
                          st.binary(max_size=12)), max_size=30))  # fmt: skip
def test_random_frames_never_raise(frames_in: list[tuple[int, bytes]]) -> None:
    dec = SbgCanDecoder(LEAP)
    for cid, data in frames_in:
        dec.feed(cid, data)
    assert dec.counters.frames + dec.counters.parse_errors >= sum(
        1 for cid, _ in frames_in if cid in sc.LAYOUTS
    )
