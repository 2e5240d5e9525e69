"""The echo ring: in-place writes, order, bounded drops, a real producer thread."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from sarmoco.daemon.echoring import EchoRing, to_complex64
from sarmoco.daemon.flags import PulseFlag
from sarmoco.errors import ProcessingError


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


def test_full_ring_drops_and_flags_next_pulse() -> None:
    ring = EchoRing(4, 3)
    assert all(_fill(ring, k) for k in range(4))
    assert not _fill(ring, 4)
    assert not _fill(ring, 5)
    assert ring.dropped == 2
    ring.pop(2)
    assert _fill(ring, 6)
    batch = ring.pop(3)
    np.testing.assert_array_equal(batch.pulse_id, [2, 3, 6])
    assert batch.flags[2] == PulseFlag.DROPPED_BEFORE
    assert batch.flags[0] == 0


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
    ring = EchoRing(64, 256, "int16")
    n_total = 20_000
    seen: list[int] = []
    done = threading.Event()

    def produce() -> None:
        for k in range(n_total):
            slot = ring.reserve()
            if slot is not None:
                slot.samples[:, 0] = k % 30_000
                slot.samples[:, 1] = -(k % 30_000)
                ring.commit(slot, t_ns=k, pulse_id=k)
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
    thread.join()
    assert seen == sorted(seen)
    assert len(seen) + ring.dropped == n_total
    assert ring.committed_total == len(seen) == ring.popped_total
