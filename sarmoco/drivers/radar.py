"""Radar echo sources: VITA 49.2 packets over UDP, TCP or from a ``.vrt`` file.

All three share one call, :meth:`RadarSource.read_into`, which decodes the
packets available within a timeout straight into the rows of a caller-provided
array (the daemon's echo ring buffer) and returns their metadata as arrays
(:class:`~sarmoco.drivers.samples.EchoPackets`), one element per row written.
"""

from __future__ import annotations

import logging
import select
import socket
import time
from abc import abstractmethod
from pathlib import Path
from typing import BinaryIO

import numpy as np
import numpy.typing as npt

from sarmoco.closing import Closing
from sarmoco.drivers.samples import EchoPacket, EchoPackets
from sarmoco.drivers.udpbatch import DatagramReceiver
from sarmoco.drivers.udpdrops import socket_drops
from sarmoco.drivers.vita49 import BATCH_MIN_PACKETS, VitaDecoder, VitaStreamFramer
from sarmoco.errors import DriverError

log = logging.getLogger(__name__)

DEFAULT_RCVBUF_BYTES = 64 * 1024 * 1024
"""Socket receive buffer asked for (the kernel caps it at net.core.rmem_max unless the
process has CAP_NET_ADMIN)."""
SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)
"""Linux: set the receive buffer past net.core.rmem_max (needs CAP_NET_ADMIN)."""
UDP_BATCH_PACKETS = 128
"""Datagrams received before they are decoded together."""
UDP_GATHER_S = 0.002
"""When a caller with room for a batch finds fewer datagrams waiting than make one, the
pause (once per call) that lets a batch build up: fewer wake-ups, batched decoding."""


KERNEL_DROPS_POLL_S = 0.5
"""How often a UDP radar link reads the kernel's drop count of its socket, s."""


class RadarSource(Closing):
    """A source of radar pulses decoded by a :class:`VitaDecoder`.

    Attributes
    ----------
    decoder : VitaDecoder
        Holds the counters (``decoder.counters``) and the last context values.
    eof : bool
        True once a file source is exhausted or a TCP peer closed the stream.
    """

    def __init__(self, decoder: VitaDecoder) -> None:
        self.decoder = decoder
        self.eof = False

    @abstractmethod
    def read_into(self, out: npt.NDArray[np.generic], timeout_s: float = 0.1) -> EchoPackets:
        """Decode the pulses available within ``timeout_s`` into ``out[0], out[1], ...``.

        Parameters
        ----------
        out : ndarray
            Preallocated rows, shape (rows, n_samples) complex64 (or
            (rows, n_samples, 2) int16 for int16 payloads). At most ``rows``
            pulses are read.
        timeout_s : float
            Longest wait for the first packet, s.

        Returns
        -------
        EchoPackets
            Metadata of the pulses written, in row order.
        """


class RadarUdpSource(RadarSource):
    """Receives one packet per datagram on a UDP port.

    Parameters
    ----------
    host, port : str, int
        Local address to bind (port 0 picks a free one; see :attr:`address`).
    decoder : VitaDecoder
        Decoder configured with the radar's profile.
    rcvbuf_bytes : int
        Socket receive buffer requested: it holds what arrives while the reader
        is descheduled. Asked with SO_RCVBUFFORCE first (honoured with
        CAP_NET_ADMIN), else SO_RCVBUF (capped at net.core.rmem_max); a smaller
        grant is logged once.
    batch_receive : bool
        Receive up to :data:`UDP_BATCH_PACKETS` datagrams per system call (``recvmmsg``,
        where the C library has it); False: one call per datagram. Either way the
        datagrams of a batch are decoded together (:meth:`VitaDecoder.decode_batch`).
    """

    def __init__(
        self,
        host: str,
        port: int,
        decoder: VitaDecoder,
        rcvbuf_bytes: int = DEFAULT_RCVBUF_BYTES,
        batch_receive: bool = True,
    ) -> None:
        super().__init__(decoder)
        try:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, rcvbuf_bytes)
            except OSError:  # no CAP_NET_ADMIN
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf_bytes)
            self._sock.bind((host, port))
        except OSError as exc:
            raise DriverError(f"radar udp {host}:{port}: cannot bind: {exc}") from exc
        self._sock.setblocking(False)
        self.address: tuple[str, int] = self._sock.getsockname()
        self.rcvbuf_bytes = self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        if self.rcvbuf_bytes < rcvbuf_bytes:  # Linux reports twice what it was asked
            log.warning(
                "radar udp %s: receive buffer %d bytes, asked %d: raise net.core.rmem_max "
                "or give the daemon CAP_NET_ADMIN, or pulses are lost whenever it stalls",
                self.address, self.rcvbuf_bytes, rcvbuf_bytes,
            )  # fmt: skip
        self.stage = np.empty((UDP_BATCH_PACKETS, decoder.max_packet_bytes + 4), np.uint8)
        """Where datagrams land, one per row (:meth:`receive`), before they are decoded."""
        self.receiver = DatagramReceiver(self._sock, self.stage, batch_receive)
        self._kernel_drops = 0
        """The kernel's drop count of the socket when last read."""
        self._kernel_drops_mono = -np.inf

    def read_into(self, out: npt.NDArray[np.generic], timeout_s: float = 0.1) -> EchoPackets:
        if time.monotonic() - self._kernel_drops_mono >= KERNEL_DROPS_POLL_S:
            self.count_kernel_drops()
        parts: list[EchoPackets] = []
        got, rows = 0, out.shape[0]
        if rows == 0 or not select.select([self], [], [], timeout_s)[0]:
            return EchoPackets.concat(parts, self.decoder.n_samples)
        gathered = rows < BATCH_MIN_PACKETS
        while got < rows:
            want = min(rows - got, UDP_BATCH_PACKETS)
            lengths = self.receive(0, want)
            if not gathered and lengths.size < BATCH_MIN_PACKETS:
                gathered = True
                time.sleep(UDP_GATHER_S)
                lengths = np.concatenate([lengths, self.receive(lengths.size, want)])
            parts.append(self.decoder.decode_batch(self.stage, lengths, out[got:]))
            got += len(parts[-1])
            if lengths.size < want:  # the socket is drained
                break
        return EchoPackets.concat(parts, self.decoder.n_samples)

    def receive(self, first: int, stop: int) -> npt.NDArray[np.int64]:
        """Receive the datagrams waiting now into rows ``first .. stop - 1`` of :attr:`stage`
        (no decoding); their lengths, bytes.

        Raises
        ------
        DriverError
            The socket failed.
        """
        try:
            return self.receiver.receive(first, stop)
        except OSError as exc:
            raise DriverError(f"radar udp {self.address}: {exc}") from exc

    def count_kernel_drops(self) -> int:
        """Add the datagrams the kernel dropped since the last look (receive buffer full)
        to ``decoder.counters.kernel_drops``, logging a warning when there are any; returns
        how many were added. Called every :data:`KERNEL_DROPS_POLL_S` by
        :meth:`read_into` and at :meth:`close`."""
        self._kernel_drops_mono = time.monotonic()
        total = socket_drops(self._sock)
        if total is None or total <= self._kernel_drops:
            return 0
        new, self._kernel_drops = total - self._kernel_drops, total
        self.decoder.counters.kernel_drops += new
        log.warning(
            "radar udp %s: the kernel dropped %d datagrams (receive buffer of %d bytes full: "
            "the reader fell behind)", self.address, new, self.rcvbuf_bytes,
        )  # fmt: skip
        return new

    def fileno(self) -> int:
        """The socket's file descriptor (to wait for datagrams with :func:`select.select`)."""
        return self._sock.fileno()

    def close(self) -> None:
        if self._sock.fileno() >= 0:
            self.count_kernel_drops()
        self._sock.close()


class _StreamRadarSource(RadarSource):
    """Common part of the byte-stream sources: read chunks, frame, decode."""

    chunk_bytes = 1 << 20

    def __init__(self, decoder: VitaDecoder) -> None:
        super().__init__(decoder)
        self._framer = VitaStreamFramer(decoder)

    @abstractmethod
    def _read_chunk(self, timeout_s: float) -> bytes | None:
        """Bytes read (b"" at end of stream) or None if nothing arrived in time."""

    def read_into(self, out: npt.NDArray[np.generic], timeout_s: float = 0.1) -> EchoPackets:
        got: list[EchoPacket] = []
        rows = out.shape[0]
        waited = False
        while len(got) < rows:
            packet = self._framer.next_packet()
            if packet is None:
                if self.eof or (waited and got):
                    break
                chunk = self._read_chunk(0.0 if waited else timeout_s)
                waited = True
                if chunk is None:
                    break
                if not chunk:
                    self.eof = True
                    break
                self._framer.feed(chunk)
                continue
            pkt = self.decoder.decode_into(packet, out[len(got)])
            self._framer.consume(packet, self.decoder.last_ok)
            if pkt is not None:
                got.append(pkt)
        return EchoPackets.of(got, self.decoder.n_samples)


class RadarTcpSource(_StreamRadarSource):
    """Connects to a radar (or simulator) serving packets back to back over TCP.

    Parameters
    ----------
    host, port : str, int
        Address of the server.
    decoder : VitaDecoder
        Decoder configured with the radar's profile.
    connect_timeout_s : float
        Longest wait for the connection, s.
    """

    def __init__(
        self, host: str, port: int, decoder: VitaDecoder, connect_timeout_s: float = 5.0
    ) -> None:
        super().__init__(decoder)
        try:
            self._sock = socket.create_connection((host, port), timeout=connect_timeout_s)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, DEFAULT_RCVBUF_BYTES)
        except OSError as exc:
            raise DriverError(f"radar tcp {host}:{port}: cannot connect: {exc}") from exc
        self._sock.setblocking(False)
        self._name = f"{host}:{port}"

    def _read_chunk(self, timeout_s: float) -> bytes | None:
        if not select.select([self._sock], [], [], timeout_s)[0]:
            return None
        try:
            data = self._sock.recv(self.chunk_bytes)
        except BlockingIOError:
            return None
        except OSError as exc:
            raise DriverError(f"radar tcp {self._name}: {exc}") from exc
        if not data:
            log.info("radar tcp %s: peer closed the stream", self._name)
        return data

    def close(self) -> None:
        self._sock.close()


class RadarFileSource(_StreamRadarSource):
    """Reads a ``.vrt`` file: the same packets back to back.

    Parameters
    ----------
    path : str or Path
        The file.
    decoder : VitaDecoder
        Decoder configured with the radar's profile.
    """

    def __init__(self, path: str | Path, decoder: VitaDecoder) -> None:
        super().__init__(decoder)
        try:
            self._file: BinaryIO = open(path, "rb")
        except OSError as exc:
            raise DriverError(f"radar file {path}: cannot open: {exc}") from exc

    def _read_chunk(self, timeout_s: float) -> bytes | None:
        return self._file.read(self.chunk_bytes)

    def close(self) -> None:
        self._file.close()
