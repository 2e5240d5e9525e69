"""Devices that vanish mid-read: every live source raises DriverError (and only that),
counts nothing bogus, and closes quietly, twice.

The daemon reopens a link on DriverError; an idle link must not raise at all.
"""

from __future__ import annotations

import os
import socket
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from sarmoco.drivers import sbg_codec as codec
from sarmoco.drivers.can_source import CanSource
from sarmoco.drivers.mavlink import MavlinkSource, mavlink2
from sarmoco.drivers.radar import RadarTcpSource, RadarUdpSource
from sarmoco.drivers.sbg import SbgSerialSource
from sarmoco.drivers.vita49 import VitaDecoder, encode_signal_packet
from sarmoco.errors import DriverError

_MAV = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
HEARTBEAT = _MAV.heartbeat_encode(1, 3, 0, 0, 0).pack(_MAV)
SBG_FRAME = codec.encode_message(codec.EkfQuat(1000, (1.0, 0.0, 0.0, 0.0), (0.0,) * 3, 0))


def raises_driver_error(poll: Callable[[], Any], tries: int = 20) -> DriverError:
    """Poll until the source notices; anything but DriverError fails the test."""
    for _ in range(tries):
        try:
            poll()
        except DriverError as exc:
            return exc
    pytest.fail("the vanished device was never reported")


def closes_quietly(src: Any) -> None:
    src.close()
    src.close()


def test_sbg_serial_pty_master_closed() -> None:
    master, slave = os.openpty()
    src = SbgSerialSource(os.ttyname(slave), 921600)
    os.write(master, SBG_FRAME)
    src.poll(0.2)
    assert src.counters.frames == 1
    assert src.poll(0.02) == []  # idle, not gone
    os.close(master)
    raises_driver_error(lambda: src.poll(0.02))
    assert src.counters.parse_errors == 0
    closes_quietly(src)
    os.close(slave)


def test_mavlink_serial_pty_master_closed() -> None:
    master, slave = os.openpty()
    src = MavlinkSource(os.ttyname(slave))
    os.write(master, HEARTBEAT)
    src.poll(0.2)
    assert src.counters.frames == 1
    os.close(master)
    raises_driver_error(lambda: src.poll(0.02))
    assert src.counters.parse_errors == 0  # (were counted by the thousand)
    closes_quietly(src)
    os.close(slave)


def test_mavlink_tcp_peer_closed(capsys: pytest.CaptureFixture[str]) -> None:
    server = socket.create_server(("127.0.0.1", 0))
    src = MavlinkSource(f"tcp:127.0.0.1:{server.getsockname()[1]}")
    conn, _ = server.accept()
    conn.sendall(HEARTBEAT)
    src.poll(0.2)
    assert src.counters.frames == 1
    assert src.poll(0.02) == []  # idle, not gone
    conn.close()
    exc = raises_driver_error(lambda: src.poll(0.02))
    assert "peer closed" in str(exc)
    assert "EOF" not in capsys.readouterr().out  # (pymavlink printed it at every read)
    closes_quietly(src)
    server.close()


def test_slcan_pty_master_closed() -> None:
    master, slave = os.openpty()
    src = CanSource.open("slcan", os.ttyname(slave), sleep_after_open=0)
    os.write(master, b"t1008" + b"00" * 8 + b"\r")
    src.poll(0.2)
    assert src.counters.frames == 1
    os.close(master)
    os.close(slave)
    exc = raises_driver_error(lambda: src.poll(0.02), tries=1)  # at once, not after 1000 errors
    assert "device gone" in str(exc)
    assert src.counters.parse_errors == 0
    closes_quietly(src)  # raised CanOperationError: slcan writes "C" to the vanished port


def test_socketcand_peer_closed() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    go = threading.Event()

    def daemon() -> None:
        conn, _ = server.accept()
        conn.sendall(b"< hi >")
        conn.recv(256)
        conn.sendall(b"< ok >")
        conn.recv(256)
        conn.sendall(b"< ok >")
        conn.sendall(f"< frame 100 0.000000 {'00' * 8} >".encode())
        go.wait(5)
        conn.close()

    th = threading.Thread(target=daemon)
    th.start()
    src = CanSource.open("socketcand", "can0", host="127.0.0.1", port=server.getsockname()[1])
    src.poll(0.2)
    assert src.counters.frames == 1
    assert src.poll(0.02) == []  # idle, not gone
    go.set()
    th.join()
    exc = raises_driver_error(lambda: src.poll(0.02))
    assert "peer closed" in str(exc)
    closes_quietly(src)
    server.close()


def test_radar_tcp_peer_closed_is_end_of_stream() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    src = RadarTcpSource("127.0.0.1", server.getsockname()[1], VitaDecoder(64, "int16"))
    conn, _ = server.accept()
    ring = np.zeros((4, 64), np.complex64)
    conn.sendall(encode_signal_packet(1, 10**18, 0, np.ones(64, np.complex64)))
    assert len(src.read_into(ring, 0.5)) == 1
    conn.close()
    for _ in range(3):  # the daemon reopens a TCP radar at end of stream
        assert len(src.read_into(ring, 0.02)) == 0
    assert src.eof
    closes_quietly(src)
    server.close()


def test_radar_udp_closes_twice() -> None:
    closes_quietly(RadarUdpSource("127.0.0.1", 0, VitaDecoder(64, "int16")))
