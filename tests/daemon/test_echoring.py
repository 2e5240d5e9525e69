"""The echo ring: in-place writes, order, bounded drops, a real producer thread."""

from __future__ import annotations

import resource
import threading
import time

import numpy as np
import pytest

from sarmoco.daemon.echoring import REORDER_WINDOW, EchoRing
from sarmoco.drivers.samples import to_complex64
from sarmoco.errors import ProcessingError
from sarmoco.store.flags import PulseFlag


def _fill(ring: EchoRing, pulse_id: int) -> bool:
    slot = ring.reserve()
    if slot is None:
        return False
    slot.samples[...] = pulse_id % 1000  # the decoder writes straight into the ring row
    ring.commit(slot, t_ns=1_000 * pulse_id, pulse_id=pulse_id, channel=pulse_id % 2)
    return True


@pytest.mark.parametrize("fmt", ["complex64", "int16"])
def test_roundtrip_in_place(fmt: str) -> None:
    ring = EchoRing(8, 5, fmt)  # type: ignore[arg-type]
    for k in range(5):
        assert _fill(ring, k)
    assert len(ring) == 5
    np.testing.assert_array_equal(ring.peek_times(3), [0, 1000, 2000])
    batch = ring.pop(4)
    assert batch.samples.shape == ((4, 5) if fmt == "complex64" else (4, 5, 2))
    np.testing.assert_array_equal(batch.pulse_id, [0, 1, 2, 3])
    np.testing.assert_array_equal(batch.channel, [0, 1, 0, 1])
    assert batch.complex_samples().dtype == np.complex64
    assert batch.complex_samples()[3, 0].real == 3
    assert len(ring) == 1


def test_int16_iq_to_complex() -> None:
    iq = np.array([[[1, -2], [3, 4]]], dtype=np.int16)
    np.testing.assert_array_equal(to_complex64(iq), [[1 - 2j, 3 + 4j]])


def test_full_ring_counts_only_real_drops_and_flags_next_pulse() -> None:
    ring = EchoRing(4, 3)
    assert all(_fill(ring, k) for k in range(4))
    for _ in range(10):  # polling a full ring while nothing arrives drops nothing
        assert ring.reserve() is None and ring.reserve_block(8) is None
    assert ring.dropped == 0
    ring.note_dropped(2)  # the reader read two pulses into scratch and discarded them
    ring.note_dropped(0)
    assert ring.dropped == 2
    ring.pop(2)
    assert _fill(ring, 6)
    assert _fill(ring, 7)
    batch = ring.pop(4)
    np.testing.assert_array_equal(batch.pulse_id, [2, 3, 6, 7])
    np.testing.assert_array_equal(batch.flags, [0, 0, PulseFlag.DROPPED_BEFORE, 0])


def test_blocks_stop_at_the_ring_end_and_give_back_unused_rows() -> None:
    ring = EchoRing(10, 2, "int16")
    a = ring.reserve_block(6)
    assert a is not None and len(a) == 6 and a.samples.shape == (6, 2, 2)
    a.samples[:4] = 7
    ring.commit_block(a, [10, 11, 12, 13], [0, 1, 2, 3], [0, 0, 1, 1], [0, 0, 0, 8])
    assert len(ring) == 4
    b = ring.reserve_block(100)  # unused rows of a went back: 6 free to the end
    assert b is not None and (b.seq, len(b)) == (4, 6)
    ring.commit_block(b, [14], [4], [0], [0])
    batch = ring.pop(5)
    np.testing.assert_array_equal(batch.t_ns, [10, 11, 12, 13, 14])
    np.testing.assert_array_equal(batch.channel, [0, 0, 1, 1, 0])
    assert batch.flags[3] == 8 and (batch.samples[:4] == 7).all()
    c = ring.reserve_block(100)  # wraps: the block never crosses the ring's end
    assert c is not None and (c.seq, len(c)) == (5, 5)
    d = ring.reserve_block(100)
    assert d is not None and (d.seq, len(d)) == (10, 5)  # positions 0..4
    ring.commit_block(d, [30, 31], [30, 31], [0, 0], [0, 0])
    assert len(ring) == 0  # c, reserved first, holds d back
    ring.commit_block(c, [20, 21], [20, 21], [0, 0], [0, 0])  # c's rest is aborted, not at head
    assert len(ring) == 4  # c's given-back rows are holes that hold nothing back
    np.testing.assert_array_equal(ring.pop(2).pulse_id, [20, 21])
    assert len(ring) == 2  # c's given-back rows are freed, d's pulses follow
    np.testing.assert_array_equal(ring.pop(2).pulse_id, [30, 31])
    assert ring.committed_total == ring.popped_total == 9 and ring.aborted_total == 0
    with pytest.raises(ProcessingError):
        ring.commit_block(c, [1], [1], [0], [0])
    e = ring.reserve_block(3)
    assert e is not None
    with pytest.raises(ProcessingError, match="4 pulses committed to a block of 3"):
        ring.commit_block(e, [1, 2, 3, 4], [1, 2, 3, 4], [0] * 4, [0] * 4)


def test_out_of_order_commit_and_abort_keep_reservation_order() -> None:
    ring = EchoRing(8, 2)
    a, b, c = ring.reserve(), ring.reserve(), ring.reserve()
    assert a is not None and b is not None and c is not None
    ring.commit(c, 30, 3)
    assert len(ring) == 0  # a and b still held
    ring.abort(a)
    assert len(ring) == 0
    ring.commit(b, 20, 2, flags=PulseFlag.SAMPLE_LOSS)
    assert len(ring) == 2
    batch = ring.pop(2)
    np.testing.assert_array_equal(batch.pulse_id, [2, 3])
    assert batch.flags[0] == PulseFlag.SAMPLE_LOSS
    with pytest.raises(ProcessingError):
        ring.commit(b, 20, 2)
    with pytest.raises(ProcessingError):
        ring.pop(1)


def test_threaded_producer_never_blocks_and_nothing_is_corrupted() -> None:
    """A reader thread writing blocks of varying fill, as the radar reader does.

    Every pulse is either consumed intact and in order or counted as dropped, and a
    pulse carries DROPPED_BEFORE exactly when pulses before it were dropped.
    """
    ring = EchoRing(64, 256, "int16")
    n_total = 20_000
    rng = np.random.default_rng(3)
    sizes = rng.integers(1, 40, n_total).tolist()
    seen: list[int] = []
    flags: list[int] = []
    done = threading.Event()

    def produce() -> None:
        k = 0
        for want in sizes:
            if k >= n_total:
                break
            arrived = min(want, n_total - k, int(rng.integers(0, want + 1)))
            block = ring.reserve_block(want)
            if block is None:
                ring.note_dropped(arrived)  # read into scratch and discarded
                k += arrived
                continue
            m = min(arrived, len(block))
            ids = np.arange(k, k + m)
            block.samples[:m, :, 0] = (ids % 30_000)[:, None]
            block.samples[:m, :, 1] = -(ids % 30_000)[:, None]
            ring.commit_block(block, ids, ids, np.zeros(m), np.zeros(m))
            k += m
        done.set()

    thread = threading.Thread(target=produce)
    thread.start()
    while not (done.is_set() and len(ring) == 0):
        n = len(ring)
        if n == 0:
            continue
        batch = ring.pop(min(n, 16))
        expect = (batch.pulse_id % 30_000).astype(np.int16)
        assert (batch.samples[:, :, 0] == expect[:, None]).all()
        assert (batch.samples[:, :, 1] == -expect[:, None]).all()
        seen.extend(batch.pulse_id.tolist())
        flags.extend(batch.flags.tolist())
    thread.join()
    assert seen == sorted(seen)
    assert ring.dropped > 0 and len(seen) + ring.dropped == n_total
    jumped = np.diff([-1, *seen]) > 1
    np.testing.assert_array_equal(np.array(flags) == PulseFlag.DROPPED_BEFORE, jumped)
    assert ring.committed_total == len(seen) == ring.popped_total


def _commit_times(ring: EchoRing, times: list[int]) -> None:
    """Commit pulses with these times, in this order; each row holds its time."""
    for t in times:
        slot = ring.reserve()
        assert slot is not None
        slot.samples[...] = t
        ring.commit(slot, t_ns=t, pulse_id=t)


def test_duplicates_are_dropped_and_late_pulses_put_back_in_order() -> None:
    ring = EchoRing(16, 3)
    _commit_times(ring, [10, 20, 20, 40, 30, 50, 10])  # a duplicate, a swap, a stale repeat
    np.testing.assert_array_equal(ring.peek_times(), [10, 20, 30, 40, 50])
    assert (ring.duplicates, ring.reordered, ring.late_dropped) == (2, 1, 0)
    batch = ring.pop(3)
    np.testing.assert_array_equal(batch.t_ns, [10, 20, 30])
    np.testing.assert_array_equal(batch.samples.real[:, 0], [10, 20, 30])  # rows moved too
    _commit_times(ring, [25, 30, 60, 45])  # 25: its place was taken; 30: the last taken
    assert len(ring) == 4  # the consumer's calls sort the new pulses out
    assert (ring.duplicates, ring.late_dropped, ring.reordered) == (3, 1, 2)
    batch = ring.pop(len(ring))
    np.testing.assert_array_equal(batch.t_ns, [40, 45, 50, 60])
    np.testing.assert_array_equal(batch.samples.real[:, 0], [40, 45, 50, 60])
    assert ring.free == 16  # the holes were freed with the pulses around them
    assert ring.committed_total == 11 and ring.popped_total == 7


def test_a_pulse_later_than_the_reorder_window_is_dropped() -> None:
    ring = EchoRing(256, 2)
    _commit_times(ring, [*range(100, 100 + 10 * (REORDER_WINDOW + 5), 10), 105, 745])
    t = ring.peek_times()
    assert ring.late_dropped == 1 and ring.reordered == 1  # 105: too far back; 745: in place
    assert (np.diff(t) > 0).all() and 105 not in t and 745 in t


def test_threaded_producer_through_a_duplicating_reordering_network() -> None:
    """1 % duplicates and 1 % swaps with the next datagram, the producer in its own thread:
    the consumer sees every pulse once, in time order, its samples intact."""
    ring = EchoRing(128, 64, "int16")
    rng = np.random.default_rng(5)
    wire: list[int] = []
    for k in range(10_000):
        wire.append(k)
        if rng.random() < 0.01:
            wire.append(k)
        if len(wire) > 1 and rng.random() < 0.01:
            wire[-1], wire[-2] = wire[-2], wire[-1]
    seen: list[int] = []
    done = threading.Event()

    def produce() -> None:
        k = 0
        while k < len(wire):
            block = ring.reserve_block(int(rng.integers(1, 20)))
            if block is None:  # wait: no drops here, every pulse must be sorted out
                time.sleep(1e-4)
                continue
            ids = np.array(wire[k : k + len(block)])
            block.samples[: ids.size, :, 0] = (ids % 30_000)[:, None]
            ring.commit_block(block, ids * 1000, ids, np.zeros(ids.size), np.zeros(ids.size))
            k += ids.size
        done.set()

    thread = threading.Thread(target=produce, daemon=True)  # a failure must not hang
    thread.start()
    while not (done.is_set() and len(ring) == 0):
        n = len(ring)
        if n:
            batch = ring.pop(min(n, 16))
            assert (batch.samples[:, :, 0] == (batch.t_ns // 1000 % 30_000)[:, None]).all()
            seen.extend((batch.t_ns // 1000).tolist())
    thread.join()
    # every datagram is taken once, or counted as a duplicate, or counted as too late (a
    # duplicate that arrives after a later pulse was taken is "late": which one it is
    # depends on the threads' timing, the sum does not)
    assert len(seen) + ring.duplicates + ring.late_dropped == len(wire)
    assert ring.duplicates > 50 and ring.reordered > 50
    assert seen == sorted(set(seen)) and set(seen) <= set(range(10_000))
    assert len(seen) >= 10_000 - ring.late_dropped


@pytest.mark.skipif(not hasattr(resource, "RUSAGE_THREAD"), reason="per-thread rusage: Linux")
def test_the_producer_writes_into_memory_the_ring_has_already_mapped() -> None:
    """Writing every slot once after construction takes no page fault: the ring wrote its
    memory itself (256 pages of 4 KiB here; written first by the producer, each was a fault)."""
    ring = EchoRing(128, 2048, "int16")  # 1 MiB: below numpy's huge-page threshold
    faults = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
    while (block := ring.reserve_block(32)) is not None:
        block.samples[...] = 7
    assert resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - faults < 16


def _popped(ring: EchoRing, n: int, t0: int) -> np.ndarray:
    """Commit ``n`` pulses from time ``t0`` (samples = their time), pop them: their samples."""
    block = ring.reserve_block(n)
    assert block is not None and len(block) == n
    t = np.arange(t0, t0 + n)
    block.samples[...] = t[:, None, None]
    ring.commit_block(block, t, t, np.zeros(n, np.int32), np.zeros(n, np.uint32))
    return ring.pop(n).samples


def test_a_pop_reuses_the_array_of_an_earlier_pop_once_nothing_refers_to_it() -> None:
    ring = EchoRing(64, 8, "int16")
    first = _popped(ring, 16, 1)
    address = first.ctypes.data
    held = _popped(ring, 16, 100)[2:5]  # a view keeps its array in use
    assert held.ctypes.data != address + 2 * held.strides[0]
    del first
    again = _popped(ring, 16, 200)
    assert again.ctypes.data == address  # reused: no fresh memory
    assert (again[:, 0, 0] == np.arange(200, 216)).all()
    more = _popped(ring, 16, 250)
    assert (held[:, 0, 0] == [102, 103, 104]).all()  # never written while in use
    assert not np.shares_memory(more, held) and not np.shares_memory(more, again)
    other = _popped(ring, 8, 300)  # another size: a new array
    assert not np.shares_memory(other, again) and not np.shares_memory(other, held)
