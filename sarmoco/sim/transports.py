"""Transports of the simulated hardware: UDP, a TCP server, a pseudo-terminal, a file.

Each link carries the bytes of one emitter (datagrams or a byte stream) and,
for duplex protocols, hands back what the peer (the daemon) sends. Links only
ever talk to the loopback interface. A link never blocks the simulator for
long: a peer that stops reading for ``stall_s`` loses the bytes (counted in
``dropped_writes``), as a real serial line or radar would.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import socket
import tty
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, BinaryIO

from sarmoco.errors import ConfigError, DriverError

SIM_HOSTS = ("127.0.0.1", "localhost")
"""Host names a simulated link may use: the IPv4 loopback only."""
STALL_S = 5.0
"""Longest wait for a peer to take bytes before they are dropped, s."""


def loopback(host: str, what: str) -> str:
    """Check that ``host`` is the loopback interface and return its IPv4 address."""
    if host not in SIM_HOSTS:
        raise ConfigError(
            f"{what}: host {host!r} is not 127.0.0.1 (the simulator only uses loopback)"
        )
    return "127.0.0.1"


class Link(ABC):
    """A transport for one emitter.

    Attributes
    ----------
    written_writes : int
        Writes delivered to the transport (datagrams or stream chunks).
    written_bytes : int
        Bytes delivered.
    dropped_writes : int
        Writes lost because no peer was there or the peer stalled.
    """

    duplex = False
    """True when the peer can send bytes back (see :meth:`receive`)."""

    def __init__(self) -> None:
        self.written_writes = 0
        self.written_bytes = 0
        self.dropped_writes = 0

    @abstractmethod
    def write(self, data: bytes) -> None:
        """Send one datagram, or append ``data`` to the stream."""

    def fds(self) -> list[int]:
        """File descriptors to watch for incoming bytes or connections."""
        return []

    def receive(self) -> bytes:
        """Bytes the peer sent since the last call (never blocks)."""
        return b""

    def peer_ready(self) -> bool:
        """Whether a peer is there to take the bytes (always True for UDP and files)."""
        return True

    @abstractmethod
    def describe(self) -> dict[str, Any]:
        """Where the link is, as JSON-able fields (``link`` and an address or path)."""

    @abstractmethod
    def close(self) -> None:
        """Release the transport; idempotent."""

    def _count(self, n: int) -> None:
        self.written_writes += 1
        self.written_bytes += n


class UdpOutLink(Link):
    """Sends datagrams to a UDP port on loopback; replies come back to the sending socket.

    Parameters
    ----------
    host, port : str, int
        Destination (the daemon's bound socket).
    """

    duplex = True

    def __init__(self, host: str, port: int) -> None:
        super().__init__()
        self.dest = (loopback(host, "udp destination"), int(port))
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 8 << 20)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.setblocking(False)
        self.source = self._sock.getsockname()

    def write(self, data: bytes) -> None:
        while True:
            try:
                self._sock.sendto(data, self.dest)
            except BlockingIOError:  # send buffer full: wait for room, then retry
                if select.select([], [self._sock], [], STALL_S)[1]:
                    continue
                self.dropped_writes += 1
                return
            except OSError as exc:
                if exc.errno not in (errno.ECONNREFUSED, errno.EHOSTUNREACH):
                    raise DriverError(f"udp to {self.dest}: {exc}") from exc
                self.dropped_writes += 1  # nobody listening yet: the datagram is lost
                return
            self._count(len(data))
            return

    def fds(self) -> list[int]:
        return [self._sock.fileno()]

    def receive(self) -> bytes:
        chunks = []
        while True:
            try:
                chunks.append(self._sock.recv(65536))
            except (BlockingIOError, ConnectionRefusedError):
                return b"".join(chunks)

    def describe(self) -> dict[str, Any]:
        return {
            "link": "udp",
            "to": f"{self.dest[0]}:{self.dest[1]}",
            "from": f"{self.source[0]}:{self.source[1]}",
        }

    def close(self) -> None:
        self._sock.close()


class TcpServerLink(Link):
    """Listens on loopback and streams to the one client connected (a newer one replaces it).

    Parameters
    ----------
    host, port : str, int
        Address to listen on (port 0 picks a free port; see :attr:`address`).
    """

    duplex = True

    def __init__(self, host: str, port: int) -> None:
        super().__init__()
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._listener.bind((loopback(host, "tcp listen address"), int(port)))
        except OSError as exc:
            raise DriverError(f"tcp {host}:{port}: cannot listen: {exc}") from exc
        self._listener.listen(1)
        self._listener.setblocking(False)
        self.address: tuple[str, int] = self._listener.getsockname()
        self._client: socket.socket | None = None
        self.connections = 0

    def _accept(self) -> None:
        try:
            conn, _ = self._listener.accept()
        except BlockingIOError:
            return
        if self._client is not None:
            self._client.close()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn.settimeout(STALL_S)
        self._client = conn
        self.connections += 1

    def _drop_client(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def write(self, data: bytes) -> None:
        if self._client is None:
            self._accept()
        if self._client is None:
            self.dropped_writes += 1
            return
        try:
            self._client.sendall(data)
        except (TimeoutError, OSError):
            self.dropped_writes += 1
            self._drop_client()
            return
        self._count(len(data))

    def fds(self) -> list[int]:
        fds = [self._listener.fileno()]
        if self._client is not None:
            fds.append(self._client.fileno())
        return fds

    def receive(self) -> bytes:
        self._accept()
        if self._client is None:
            return b""
        if not select.select([self._client], [], [], 0)[0]:
            return b""
        try:
            data = self._client.recv(65536)
        except OSError:
            data = b""
        if not data:
            self._drop_client()
        return data

    def peer_ready(self) -> bool:
        self._accept()
        return self._client is not None

    def describe(self) -> dict[str, Any]:
        return {"link": "tcp", "listen": f"{self.address[0]}:{self.address[1]}"}

    def close(self) -> None:
        self._drop_client()
        self._listener.close()


class PtyLink(Link):
    """The device side of a pseudo-terminal; the daemon opens :attr:`path` as a serial port.

    The slave is put in raw mode and closed here, so :meth:`peer_ready` is True
    exactly while someone has it open (the master reports hang-up otherwise).
    Bytes written before the peer opens it wait in the terminal's buffer.
    """

    duplex = True

    def __init__(self) -> None:
        super().__init__()
        self._master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        os.set_blocking(self._master, False)
        self._poll = select.poll()
        self._poll.register(self._master, select.POLLIN | select.POLLOUT)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                if not select.select([], [self._master], [], STALL_S)[1]:
                    self.dropped_writes += 1
                    return
                continue
            view = view[n:]
        self._count(len(data))

    def fds(self) -> list[int]:
        # with no peer the master polls readable (hang-up) forever: do not watch it then
        return [self._master] if self.peer_ready() else []

    def receive(self) -> bytes:
        chunks = []
        while True:
            try:
                chunk = os.read(self._master, 65536)
            except (BlockingIOError, OSError):  # EIO: the peer closed the slave
                break
            if not chunk:
                break
            chunks.append(chunk)
        return b"".join(chunks)

    def peer_ready(self) -> bool:
        return not any(ev & select.POLLHUP for _, ev in self._poll.poll(0))

    def describe(self) -> dict[str, Any]:
        return {"link": "pty", "path": self.path}

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self._master)


class FileLink(Link):
    """Writes the bytes to a file (the same bytes a live link would carry).

    Parameters
    ----------
    path : str or Path
        File to create (truncated if it exists).
    """

    def __init__(self, path: str | Path) -> None:
        super().__init__()
        self.path = Path(path)
        try:
            self._file: BinaryIO = open(self.path, "wb")
        except OSError as exc:
            raise DriverError(f"file {self.path}: cannot create: {exc}") from exc

    def write(self, data: bytes) -> None:
        self._file.write(data)
        self._count(len(data))

    def describe(self) -> dict[str, Any]:
        return {"link": "file", "path": str(self.path)}

    def close(self) -> None:
        self._file.close()
