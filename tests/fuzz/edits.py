"""How the fuzz tests damage valid bytes: a few random edits, the generic ones shared.

Every byte-stream harness starts from frames of the project's own encoders and damages
them with :func:`edited`: bit flips, a cut, bytes inserted, garbage appended, plus the
edits of its own format (a length field rewritten, a header word replaced), given as
functions that edit the buffer in place.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from hypothesis import strategies as st

FormatEdit = Callable[[Any, bytearray], None]
"""A format's own edit: ``edit(draw, buf)`` changes ``buf`` in place (hypothesis ``draw``)."""


@st.composite
def edited(
    draw: Any,
    data: bytes,
    *,
    count: tuple[int, int] = (0, 3),
    max_insert: int = 8,
    max_append: int = 0,
    format_edits: Mapping[str, FormatEdit] | None = None,
) -> bytes:
    """``data`` with ``count`` (inclusive range) random edits.

    Parameters
    ----------
    draw : hypothesis draw function
        Supplied by :func:`hypothesis.strategies.composite`.
    data : bytes
        The valid frame or packet.
    count : tuple of int
        Fewest and most edits.
    max_insert : int
        Most bytes one insertion adds at a random position (at least 1).
    max_append : int
        Most garbage bytes one append adds at the end; 0: no appending.
    format_edits : mapping of str to FormatEdit, optional
        The format's own edits by name, drawn alongside ``flip``, ``cut``, ``insert`` and
        ``append``.
    """
    own = dict(format_edits or {})
    ops = ["flip", "cut", "insert", *(["append"] if max_append else []), *own]
    buf = bytearray(data)
    for _ in range(draw(st.integers(*count))):
        op = draw(st.sampled_from(ops))
        if op in own:
            own[op](draw, buf)
            continue
        pos = draw(st.integers(0, max(len(buf) - 1, 0)))
        if op == "flip" and buf:
            buf[pos] ^= 1 << draw(st.integers(0, 7))
        elif op == "cut":
            del buf[pos:]
        elif op == "insert":
            buf[pos:pos] = draw(st.binary(min_size=1, max_size=max_insert))
        elif op == "append":
            buf += draw(st.binary(min_size=1, max_size=max_append))
    return bytes(buf)
