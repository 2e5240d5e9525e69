"""Datagrams the kernel discarded for a UDP socket whose receive buffer was full.

A datagram that finds the socket's receive buffer full is dropped by the kernel before
any reader sees it; its loss shows in the stream only as a gap (for VITA 49, a 4-bit
packet count that cannot size a long gap). Linux counts these drops per socket, in the
last column (``drops``) of ``/proc/net/udp`` (``/proc/net/udp6`` for IPv6 sockets), on the
line of the socket's inode. :func:`socket_drops` reads that count; elsewhere it is None.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

PROC_TABLES = (Path("/proc/net/udp"), Path("/proc/net/udp6"))
"""Linux's tables of UDP sockets, IPv4 and IPv6."""


def socket_drops(sock: socket.socket) -> int | None:
    """Datagrams the kernel dropped for ``sock`` since it was opened (None: not known here).

    Parameters
    ----------
    sock : socket.socket
        An open UDP socket of this process.

    Returns
    -------
    int or None
        The kernel's drop count for the socket (receive buffer full), or None where the
        table is not readable or does not list the socket (not Linux, a closed socket).
    """
    try:
        inode = str(os.fstat(sock.fileno()).st_ino)
    except OSError:
        return None
    for table in PROC_TABLES:
        try:
            lines = table.read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) >= 13 and fields[9] == inode:
                return int(fields[-1])
    return None
