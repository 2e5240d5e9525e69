"""The focus backlog: bounded, skips the oldest pulses ahead, never those a look has seen."""

from __future__ import annotations

import numpy as np
import pytest

from sarmoco.daemon.backlog import FocusBacklog, RecordedBatch
from sarmoco.errors import ProcessingError


def _batch(first: int, n: int) -> RecordedBatch:
    """Pulses ``first .. first + n - 1``: time = id = row = that number."""
    k = np.arange(first, first + n, dtype=np.int64)
    return RecordedBatch(
        samples=np.zeros((n, 4, 2), dtype=np.int16),
        t_ns=k,
        pulse_id=k,
        channel=np.zeros(n, dtype=np.int32),
        flags=np.zeros(n, dtype=np.uint32),
        row=k,
    )


def test_pops_in_order_across_puts() -> None:
    b = FocusBacklog(10)
    b.put(_batch(0, 3))
    b.put(_batch(3, 4))
    np.testing.assert_array_equal(b.peek_times(5), np.arange(5))
    got = b.pop(5)
    np.testing.assert_array_equal(got.row, np.arange(5))
    assert len(b) == 2 and b.free == 8 and b.oldest_ns() == 5
    assert b.skipped == 0


def test_a_full_backlog_skips_its_oldest_pulses_ahead() -> None:
    b = FocusBacklog(5)
    b.put(_batch(0, 4))
    assert b.put(_batch(4, 3)) == 2
    np.testing.assert_array_equal(b.pop(5).t_ns, np.arange(2, 7))
    assert b.put(_batch(7, 8)) == 3  # more than it holds at once: the newest stay
    np.testing.assert_array_equal(b.peek_times(), np.arange(10, 15))
    assert b.skipped == 5


def test_pulses_a_look_saw_are_not_skipped() -> None:
    """Between the aligner's look and its pop the recorder may put more: the pop takes
    exactly what the look saw; the pulses after them are skipped instead."""
    b = FocusBacklog(4)
    b.put(_batch(0, 4))
    seen = b.peek_times(2)
    b.put(_batch(4, 3))
    np.testing.assert_array_equal(b.pop(2).t_ns, seen)
    np.testing.assert_array_equal(b.peek_times(), [5, 6])
    assert b.skipped == 3


def test_pop_of_more_than_waits_is_refused() -> None:
    b = FocusBacklog(4)
    b.put(_batch(0, 2))
    with pytest.raises(ProcessingError):
        b.pop(3)
