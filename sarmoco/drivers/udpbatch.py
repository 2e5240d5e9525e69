"""Many UDP datagrams per system call, received straight into the rows of an array.

Linux's ``recvmmsg(2)`` (called through :mod:`ctypes`, which releases the GIL during the
call) fills up to ``vlen`` buffers with one datagram each and returns how many it filled:
one system call and one Python call for a whole batch, where :meth:`socket.socket.recv_into`
costs both per datagram. Where the C library has no ``recvmmsg`` (or the caller asks for it),
:class:`DatagramReceiver` falls back to ``recv_into`` per datagram with the same result.

A datagram longer than its row is cut to the row's length, in both ways (the length
returned is the row's): a decoder that knows the largest valid packet sees the cut one as
too long.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import socket

import numpy as np
import numpy.typing as npt

from sarmoco.errors import DriverError

MSG_DONTWAIT = 0x40
"""Linux ``MSG_DONTWAIT``: return at once when no datagram is waiting."""


class _IoVec(ctypes.Structure):
    _fields_ = [("iov_base", ctypes.c_void_p), ("iov_len", ctypes.c_size_t)]


class _MsgHdr(ctypes.Structure):
    _fields_ = [
        ("msg_name", ctypes.c_void_p),
        ("msg_namelen", ctypes.c_uint32),
        ("msg_iov", ctypes.POINTER(_IoVec)),
        ("msg_iovlen", ctypes.c_size_t),
        ("msg_control", ctypes.c_void_p),
        ("msg_controllen", ctypes.c_size_t),
        ("msg_flags", ctypes.c_int),
    ]


class _MMsgHdr(ctypes.Structure):
    _fields_ = [("msg_hdr", _MsgHdr), ("msg_len", ctypes.c_uint)]


def _libc_recvmmsg() -> ctypes._CFuncPtr | None:  # type: ignore[name-defined]
    """The C library's ``recvmmsg``, or None where there is none."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        func = libc.recvmmsg
    except (OSError, AttributeError, TypeError):
        return None
    func.argtypes = [
        ctypes.c_int, ctypes.POINTER(_MMsgHdr), ctypes.c_uint, ctypes.c_int, ctypes.c_void_p
    ]  # fmt: skip
    func.restype = ctypes.c_int
    return func


_RECVMMSG = _libc_recvmmsg()


class DatagramReceiver:
    """Receives datagrams from a non-blocking UDP socket into the rows of ``stage``.

    Parameters
    ----------
    sock : socket.socket
        A bound, non-blocking datagram socket (the caller keeps and closes it).
    stage : ndarray of uint8, shape (rows, row_bytes), C-contiguous
        Where datagram ``i`` of a call lands (``stage[i, :length]``); it must live as
        long as the receiver.
    batched : bool
        Use ``recvmmsg`` when the C library has it; False: ``recv_into`` per datagram.

    Attributes
    ----------
    batched : bool
        Whether ``recvmmsg`` is used.
    """

    def __init__(self, sock: socket.socket, stage: npt.NDArray[np.uint8], batched: bool = True):
        if stage.dtype != np.uint8 or stage.ndim != 2 or not stage.flags.c_contiguous:
            raise DriverError("datagram stage: a C-contiguous uint8 array of rows is needed")
        self._sock = sock
        self._stage = stage
        self.batched = batched and _RECVMMSG is not None
        self._views = [memoryview(row) for row in stage]
        rows, row_bytes = stage.shape
        self._iov = (_IoVec * rows)()
        self._msgs = (_MMsgHdr * rows)()
        base = stage.ctypes.data
        for i in range(rows):
            self._iov[i].iov_base = base + i * row_bytes
            self._iov[i].iov_len = row_bytes
            self._msgs[i].msg_hdr.msg_iov = ctypes.pointer(self._iov[i])
            self._msgs[i].msg_hdr.msg_iovlen = 1
        self._lengths = np.ndarray(
            (rows,),
            dtype=np.uint32,
            buffer=self._msgs,
            offset=_MMsgHdr.msg_len.offset,
            strides=(ctypes.sizeof(_MMsgHdr),),
        )
        """``msg_len`` of every entry of the ``recvmmsg`` vector, read in place."""

    def receive(self, first: int, stop: int) -> npt.NDArray[np.int64]:
        """Receive the datagrams waiting now into rows ``first .. stop - 1``, in order.

        Returns
        -------
        ndarray of int64
            Length of each datagram received, bytes (fewer than ``stop - first`` when the
            socket ran dry).

        Raises
        ------
        OSError
            The socket failed (anything but "nothing waiting").
        """
        if first >= stop:
            return np.zeros(0, np.int64)
        if not self.batched:
            return self._receive_each(first, stop)
        assert _RECVMMSG is not None
        n = _RECVMMSG(
            self._sock.fileno(), ctypes.byref(self._msgs[first]), stop - first, MSG_DONTWAIT, None
        )
        if n < 0:
            err = ctypes.get_errno()
            if err in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EINTR):
                return np.zeros(0, np.int64)
            raise OSError(err, f"recvmmsg: {errno.errorcode.get(err, err)}")
        return self._lengths[first : first + n].astype(np.int64)

    def _receive_each(self, first: int, stop: int) -> npt.NDArray[np.int64]:
        lengths: list[int] = []
        recv_into = self._sock.recv_into
        try:
            for view in self._views[first:stop]:
                lengths.append(recv_into(view))
        except BlockingIOError:
            pass
        return np.array(lengths, np.int64)
