"""The host's UTC clock on the monotonic clock (:mod:`sarmoco.drivers.hostclock`): slews
followed, steps held for judging, reads interrupted by the scheduler not taken for steps."""

from __future__ import annotations

from sarmoco.drivers.hostclock import HostClock

MS = 1_000_000


class Machine:
    """A fake machine: monotonic time advances 1 µs per read; the wall clock is monotonic
    time plus ``offset``; ``pause_ns`` descheduled time comes once, after the next monotonic
    read."""

    def __init__(self) -> None:
        self.mono_ns = 10**12
        self.offset = 1_700_000_000 * 10**9
        self.pause_ns = 0

    def mono(self) -> int:
        self.mono_ns += 1000
        now = self.mono_ns
        self.mono_ns += self.pause_ns
        self.pause_ns = 0
        return now

    def wall(self) -> int:
        self.mono_ns += 1000
        return self.mono_ns + self.offset


def test_slews_followed_steps_held_then_adopted_or_not() -> None:
    m = Machine()
    clock = HostClock(m.wall, m.mono)
    assert abs(clock.now_ns() - (m.mono_ns + m.offset)) < 10_000
    m.offset += 2 * MS // 1000  # a slew's worth: followed
    assert abs(clock.now_ns() - (m.mono_ns + m.offset)) < 10_000 and clock.take_step() == 0
    m.offset += 10 * 10**9  # a step: held
    assert abs(clock.now_ns() - (m.mono_ns + m.offset - 10 * 10**9)) < 10_000
    assert clock.take_step() == 10 * 10**9 and clock.take_step() == 0
    clock.adopt(10 * 10**9)
    assert abs(clock.now_ns() - (m.mono_ns + m.offset)) < 10_000
    m.offset -= 3600 * 10**9
    clock.now_ns()
    assert clock.take_step() == -3600 * 10**9  # not adopted: the clock stays where it was
    assert abs(clock.now_ns() - (m.mono_ns + m.offset + 3600 * 10**9)) < 10_000
    assert clock.take_step() == 0  # the same step is not seen twice


def test_a_thread_descheduled_mid_read_is_no_step() -> None:
    m = Machine()
    clock = HostClock(m.wall, m.mono)
    for pause_ms in (15, 200, 2000):
        m.pause_ns = pause_ms * MS  # between the monotonic read and the wall read after it
        assert abs(clock.now_ns() - (m.mono_ns + m.offset)) < 10_000
        assert clock.take_step() == 0
