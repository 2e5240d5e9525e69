"""A UART line read at the wrong baud rate: what a serial receiver makes of a sender's bytes.

Each byte goes on the line as a start bit (0), eight data bits (least significant first)
and a stop bit (1); the line idles at 1. A receiver running at ``ratio`` times the
sender's rate waits for a falling edge, samples the middle of each of its own bit
periods and delivers a byte per start bit, even when the stop bit reads 0 (a framing
error the driver above never sees). This is how sbgECom frames arrive when the
configured ``ins.baudrate`` is not the INS's.
"""

from __future__ import annotations

import numpy as np

OVERSAMPLE = 16
"""Line samples per sender bit."""


def misread(data: bytes, ratio: float) -> bytes:
    """The bytes a receiver at ``ratio`` x the sender's baud rate reads from ``data``.

    Parameters
    ----------
    data : bytes
        What the sender transmits, back to back.
    ratio : float
        Receiver baud rate over the sender's (> 0; 1 reads ``data`` back).

    Returns
    -------
    bytes
        One byte per start bit the receiver finds.
    """
    raw = np.frombuffer(data, dtype=np.uint8)
    bits = np.unpackbits(raw[:, None], axis=1, bitorder="little")
    frames = np.concatenate([np.zeros((raw.size, 1)), bits, np.ones((raw.size, 1))], axis=1)
    line = np.concatenate([np.repeat(frames.ravel(), OVERSAMPLE), np.ones(OVERSAMPLE * 20)])
    bit = OVERSAMPLE / ratio  # one receiver bit, in line samples
    out = bytearray()
    i = 0
    while True:
        low = np.flatnonzero(line[i:] == 0)
        if low.size == 0:
            return bytes(out)
        start = i + int(low[0])
        at = (start + (np.arange(1, 9) + 0.5) * bit).astype(np.int64)
        sampled = line[np.minimum(at, line.size - 1)].astype(np.uint8)
        out.append(int(np.packbits(sampled, bitorder="little")[0]))
        i = min(int(start + 9.5 * bit), line.size - 1) + 1
        if i >= line.size:
            return bytes(out)
