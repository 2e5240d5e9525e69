"""The navigation buffer: order, duplicates, history, eviction, clock consistency."""

from __future__ import annotations

import numpy as np

from sarmoco.daemon.navbuffer import NO_TIME, NavBuffer, NavStream
from sarmoco.drivers.samples import AttitudeSample, Validity, VelocitySample
from sarmoco.processing.types import NavSamples
from sarmoco.store.flags import PushResult

MS = 1_000_000


def _stream(**kw: int) -> NavStream:
    args = {
        "history_ns": 1000 * MS,
        "capacity": 64,
        "clock_tolerance_ns": 20 * MS,
        "rebase_after_ns": 500 * MS,
    }
    args.update(kw)
    return NavStream(1, **args)


def test_late_samples_are_inserted_in_order_and_duplicates_refused() -> None:
    s = _stream()
    for t in (0, 10, 30, 20, 5):
        assert s.push(t * MS, [t]) is PushResult.ACCEPTED
    assert s.push(20 * MS, [99]) is PushResult.DUPLICATE
    np.testing.assert_array_equal(s.t_ns, np.array([0, 5, 10, 20, 30]) * MS)
    np.testing.assert_array_equal(s.values[:, 0], [0, 5, 10, 20, 30])
    assert s.counts["reordered"] == 2


def test_history_is_bounded_and_stale_samples_dropped() -> None:
    s = _stream(history_ns=100 * MS)
    for t in range(0, 300, 10):
        s.push(t * MS, [t])
    assert s.t_ns[0] == 190 * MS and s.t_ns[-1] == 290 * MS
    assert s.push(150 * MS, [0]) is PushResult.STALE
    assert s.counts["stale"] == 1


def test_a_hold_keeps_the_samples_from_its_time_beyond_the_history() -> None:
    """What a lagging focuser has not reached stays (two samples before it too); once the
    hold moves on or is lifted, the history alone decides again."""
    s = _stream(history_ns=100 * MS)
    s.hold(120 * MS)
    for t in range(0, 300, 10):
        s.push(t * MS, [t])
    assert s.t_ns[0] == 100 * MS and s.t_ns[-1] == 290 * MS
    s.hold(None)
    s.push(300 * MS, [300])
    assert s.t_ns[0] == 200 * MS


def test_capacity_evicts_the_oldest() -> None:
    s = _stream(capacity=8)
    for t in range(20):
        s.push(t * MS, [t])
    assert len(s) == 8
    np.testing.assert_array_equal(s.t_ns, np.arange(12, 20) * MS)
    assert s.counts["evicted"] > 0


def test_bracket_and_window() -> None:
    s = _stream()
    for t in (10, 20, 40):
        s.push(t * MS, [t])
    before, after = s.bracket(np.array([5, 10, 25, 45]) * MS)
    np.testing.assert_array_equal(before, [NO_TIME, 10 * MS, 20 * MS, 40 * MS])
    np.testing.assert_array_equal(after, [10 * MS, 10 * MS, 40 * MS, NO_TIME])
    t, v = s.window(20 * MS, 25 * MS)
    np.testing.assert_array_equal(t, np.array([10, 20, 40]) * MS)
    assert v.shape == (3, 1)


def test_clock_step_is_refused_then_a_persistent_change_rebases() -> None:
    s = _stream(rebase_after_ns=200 * MS)
    rx = lambda t: t + 3 * MS  # noqa: E731  (a link with 3 ms latency)
    for t in range(0, 100, 5):
        assert s.push(t * MS, [t], rx_ns=rx(t * MS)) is PushResult.ACCEPTED
    # The INS clock jumps 80 ms ahead: stamps no longer match arrival.
    for t in range(100, 200, 5):
        assert s.push((t + 80) * MS, [t], rx_ns=rx(t * MS)) is PushResult.CLOCK_REJECTED
    # The clock mapping corrects itself: accepted again, the refused span is a gap.
    assert s.push(200 * MS, [200], rx_ns=rx(200 * MS)) is PushResult.ACCEPTED
    before, after = s.bracket(np.array([150 * MS]))
    assert after[0] - before[0] == 105 * MS
    # A change that persists longer than rebase_after_ns becomes the new normal,
    # with nothing before the change mixed in.
    results = [s.push((t + 80) * MS, [t], rx_ns=rx(t * MS)) for t in range(205, 500, 5)]
    assert results[0] is PushResult.CLOCK_REJECTED and results[-1] is PushResult.ACCEPTED
    assert s.counts["rebased"] == 1
    assert s.t_ns[0] > 200 * MS + 80 * MS


def test_driver_and_joint_samples() -> None:
    buf = NavBuffer(history_ns=5_000 * MS, capacity=128)
    v = VelocitySample(1000, (30.0, 0.1, 0.0), Validity.VELOCITY, "test", 0, pos_ned=(1, 2, 3))
    a = AttitudeSample(1000, (1.0, 0.0, 0.0, 0.0), Validity.ATTITUDE, "test", 0)
    assert buf.push_sample(v) is PushResult.ACCEPTED
    assert buf.push_sample(a) is PushResult.ACCEPTED
    nav = NavSamples(np.array([2000, 1000]), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)))
    res = buf.push_nav(nav)
    assert list(res) == [PushResult.ACCEPTED, PushResult.DUPLICATE]
    np.testing.assert_array_equal(buf.kinematics.values[0], [30.0, 0.1, 0.0, 1, 2, 3])
    assert np.isnan(buf.kinematics.values[1, 3:]).all()
    assert buf.counts()["attitude_duplicate"] == 1
