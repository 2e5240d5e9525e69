"""What every fuzz test asserts: bounded allocation, and errors of the project's tree only;
and the reads a stream harness feeds (a bounded buffer is checked after each)."""

from __future__ import annotations

import tracemalloc
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

from sarmoco.errors import SarmocoError

ALLOC_CAP_BYTES = 4 << 20
"""Peak Python and numpy allocation allowed while one fuzz example is decoded, bytes
(every decoder under test needs far less; a decoder that believed a header's length
field would ask for up to 256 KiB (VITA), 64 KiB (sbgECom) or gigabytes (a store's
shape), so the cap sits above the honest need and below what a lie would cost)."""


@contextmanager
def bounded_allocation(cap_bytes: int = ALLOC_CAP_BYTES) -> Iterator[None]:
    """Fail if the block's peak traced allocation (Python objects and numpy buffers,
    which numpy reports to :mod:`tracemalloc`) exceeds ``cap_bytes``."""
    tracemalloc.start()
    try:
        yield
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= cap_bytes, f"peak allocation {peak} B > cap {cap_bytes} B"


def assert_named_error(exc: BaseException, *names: str) -> None:
    """``exc`` is one of sarmoco's own errors and its message names one of ``names``."""
    assert isinstance(exc, SarmocoError), f"{type(exc).__name__}: {exc}"
    text = str(exc)
    assert any(n in text for n in names), f"{text!r} names none of {names}"


def stream_reads(stream: bytes, sizes: Sequence[int]) -> Iterator[tuple[bytes, bool]]:
    """``stream`` cut into reads of ``sizes`` bytes (cycled, each >= 1), in order: each
    read and whether it is the last (a file's end). A decoder's buffer may hold one
    maximal frame plus the read just fed, never more."""
    pos, k = 0, 0
    while pos < len(stream):
        end = pos + sizes[k % len(sizes)]
        yield stream[pos:end], end >= len(stream)
        pos, k = end, k + 1
