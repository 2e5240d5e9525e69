"""A UART line read at the wrong baud rate (sarmoco.sim.uart), checked bit by bit."""

from __future__ import annotations

import numpy as np

from sarmoco.sim.uart import misread


def test_same_rate_reads_every_byte_back() -> None:
    data = np.random.default_rng(3).integers(0, 256, 500, dtype=np.uint8).tobytes()
    assert misread(data, 1.0) == data


def test_double_and_half_rate_by_hand() -> None:
    """0xFF at twice the rate: the second half of the start bit is read as data bit 0
    (0xFE), the rest is idle line. 0x00 at half the rate: the receiver's bits 0-2 fall in
    the sender's low data bits, bit 3 on its stop bit, bits 4-7 on the idle line (0xF8)."""
    assert misread(b"\xff", 2.0) == b"\xfe"
    assert misread(b"\x00", 0.5) == b"\xf8"
