"""The fuzz harnesses' damage reaches every kind of edit it offers."""

from __future__ import annotations

from typing import Any

from hypothesis import find

from tests.fuzz.edits import edited

DATA = bytes(range(1, 33))


def _mark(draw: Any, buf: bytearray) -> None:
    buf[0] = 0


def test_each_edit_is_reachable() -> None:
    strategy = edited(DATA, count=(1, 1), max_insert=1, max_append=4, format_edits={"mark": _mark})
    flipped = find(strategy, lambda b: len(b) == len(DATA) and b[0] != 0 and b != DATA)
    assert bin(int.from_bytes(flipped, "big") ^ int.from_bytes(DATA, "big")).count("1") == 1
    assert find(strategy, lambda b: len(b) < len(DATA)) == DATA[:0]  # a cut at the start
    longer = find(strategy, lambda b: len(b) > len(DATA) and not b.startswith(DATA))
    assert len(longer) == len(DATA) + 1  # one byte inserted before the end
    assert find(strategy, lambda b: len(b) > len(DATA) + 1)[: len(DATA)] == DATA  # appended
    assert find(strategy, lambda b: b[:1] == b"\0")[1:] == DATA[1:]  # the format's own edit
    assert find(edited(DATA, count=(0, 0)), lambda b: True) == DATA
