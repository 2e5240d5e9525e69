"""sd_notify client against a real AF_UNIX datagram socket."""

from __future__ import annotations

import os
import socket
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from sarmoco.daemon.sdnotify import Notifier
from sarmoco.errors import DriverError


@pytest.fixture
def path_socket(tmp_path: Path) -> Iterator[tuple[socket.socket, str]]:
    path = str(tmp_path / "notify.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(path)
    sock.settimeout(2.0)
    yield sock, path
    sock.close()


@pytest.fixture
def abstract_socket() -> Iterator[tuple[socket.socket, str]]:
    name = f"sarmoco-test-{uuid.uuid4().hex}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(b"\0" + name.encode())
    sock.settimeout(2.0)
    yield sock, "@" + name
    sock.close()


def _exchange(sock: socket.socket, notifier: Notifier) -> list[bytes]:
    notifier.ready(status="starting")
    notifier.status("12.0 kpulse/s, INS age 8 ms\nbacklog 0")
    notifier.watchdog()
    notifier.extend_timeout(5_000_000)
    notifier.stopping()
    notifier.close()
    return [sock.recv(4096) for _ in range(5)]


@pytest.mark.parametrize("kind", ["path_socket", "abstract_socket"])
def test_messages_arrive(kind: str, request: pytest.FixtureRequest) -> None:
    sock, name = request.getfixturevalue(kind)
    notifier = Notifier({"NOTIFY_SOCKET": name})
    assert notifier.enabled
    got = _exchange(sock, notifier)
    assert got == [
        b"READY=1\nSTATUS=starting",
        b"STATUS=12.0 kpulse/s, INS age 8 ms backlog 0",
        b"WATCHDOG=1",
        b"EXTEND_TIMEOUT_USEC=5000000",
        b"STOPPING=1",
    ]


def test_noop_when_unset() -> None:
    notifier = Notifier({})
    assert not notifier.enabled
    notifier.ready()
    notifier.watchdog()
    assert notifier.watchdog_interval_s is None


def test_watchdog_usec_and_pid() -> None:
    mine = Notifier({"WATCHDOG_USEC": "2500000", "WATCHDOG_PID": str(os.getpid())})
    assert mine.watchdog_interval_s == 2.5
    other = Notifier({"WATCHDOG_USEC": "2500000", "WATCHDOG_PID": str(os.getpid() + 1)})
    assert other.watchdog_interval_s is None
    no_pid = Notifier({"WATCHDOG_USEC": "1000"})
    assert no_pid.watchdog_interval_s == 0.001


def test_bad_socket_name_and_dead_socket(tmp_path: Path) -> None:
    with pytest.raises(DriverError, match="neither a path"):
        Notifier({"NOTIFY_SOCKET": "relative/name"})
    dead = Notifier({"NOTIFY_SOCKET": str(tmp_path / "nobody-listens")})
    with pytest.raises(DriverError, match="sd_notify"):
        dead.ready()


def test_keepalive_at_most_every_half_watchdog_interval(
    path_socket: tuple[socket.socket, str],
) -> None:
    sock, name = path_socket
    notifier = Notifier({"NOTIFY_SOCKET": name, "WATCHDOG_USEC": "2000000"})
    sent = [t for t in (10.0, 10.5, 10.99, 11.0, 11.2, 12.1, 13.0) if notifier.keepalive(t)]
    assert sent == [10.0, 11.0, 12.1]
    assert [sock.recv(4096) for _ in sent] == [b"WATCHDOG=1"] * 3
    assert not Notifier({"NOTIFY_SOCKET": name}).keepalive(10.0)  # systemd does not watch
