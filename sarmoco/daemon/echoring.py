"""Preallocated ring of radar pulses, written in place by the decoder.

The radar reader thread reserves a block of contiguous slots
(:meth:`EchoRing.reserve_block`, or one slot with :meth:`EchoRing.reserve`),
lets the decoder write the samples straight into them (no intermediate copy)
and publishes the rows it filled with :meth:`EchoRing.commit_block` (or
:meth:`EchoRing.commit`). The consumer (the aligner) looks at the oldest
committed pulses with :meth:`EchoRing.peek_times` and takes them out with
:meth:`EchoRing.pop`. The ring is bounded and never blocks the producer: when
it is full, a reservation returns ``None``; the producer then reads the waiting
packets into scratch space and reports them with :meth:`EchoRing.note_dropped`,
which counts them and flags the next committed pulse
:attr:`~sarmoco.store.flags.PulseFlag.DROPPED_BEFORE`. A full ring polled
while nothing arrives counts nothing.

Pulses leave the ring in time order, each time once. Any number of producers
may hold slots at once; a reserved slot that is neither committed nor given back
holds back the pulses reserved after it. The consumer's looks (``len``,
:meth:`EchoRing.peek_times`; one thread, the one that calls :meth:`EchoRing.pop`)
first sort out what the network did to the committed pulses not seen yet
(:meth:`EchoRing.pop` takes the pulses looked at):

- a pulse whose time equals that of a pulse still waiting, or of the last one
  taken, is a duplicate: counted (:attr:`EchoRing.duplicates`) and discarded;
- a pulse older than the newest one waiting (a reordered datagram) is put back
  in time order (:attr:`EchoRing.reordered`) when its place is among the last
  :data:`REORDER_WINDOW` waiting pulses; one whose place has already been taken
  out of the ring, or lies further back, is counted
  (:attr:`EchoRing.late_dropped`) and discarded.

A discarded pulse leaves a hole in the ring that is freed with the pulses around
it; the producer is never held back by it.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sarmoco.drivers.samples import SampleFormat, sample_dtype, sample_shape, to_complex64
from sarmoco.errors import ProcessingError
from sarmoco.processing.types import IntArray
from sarmoco.store.flags import FLAG_DTYPE, PulseFlag

_FREE, _RESERVED, _COMMITTED, _ABORTED = 0, 1, 2, 3
"""Slot states; ``_ABORTED`` also marks a discarded pulse (a hole waiting to be freed)."""

REORDER_WINDOW = 64
"""Waiting pulses among which a late pulse is put back in place: a pulse late by more is
dropped (bounds the rows moved per late pulse)."""
_HELD_BY_POOL = 3
"""Reference count of an array of :attr:`EchoRing._handed` that nothing else refers to, as
:meth:`EchoRing._spare` reads it (the list, a local name, ``sys.getrefcount``'s own)."""
SORT_RUN = 1024
"""Most new slots the consumer's look checks with one set of array operations (pulses in
time order); a slot out of order is checked on its own, and the next run starts after it."""


@dataclass(frozen=True)
class Slot:
    """A reserved ring slot.

    Attributes
    ----------
    seq : int
        Running reservation number (ring position = ``seq % capacity``).
    samples : ndarray
        View of the slot's row: complex64 ``(S,)`` or int16 ``(S, 2)``. The
        decoder writes the pulse here before :meth:`EchoRing.commit`; rows it
        does not fill keep whatever an earlier pulse left.
    """

    seq: int
    samples: npt.NDArray[np.generic]


@dataclass(frozen=True)
class Block:
    """Contiguous reserved ring slots (a block never wraps around the ring's end).

    Attributes
    ----------
    seq : int
        Reservation number of the first slot (ring position = ``seq % capacity``).
    samples : ndarray
        View of the rows: complex64 ``(n, S)`` or int16 ``(n, S, 2)``. The decoder
        writes pulse ``k`` into ``samples[k]`` before :meth:`EchoRing.commit_block`.
    """

    seq: int
    samples: npt.NDArray[np.generic]

    def __len__(self) -> int:
        return int(self.samples.shape[0])


@dataclass(frozen=True)
class EchoBatch:
    """Pulses taken out of the ring (copies, oldest first).

    Attributes
    ----------
    samples : ndarray
        complex64 ``(P, S)`` or int16 ``(P, S, 2)``, as held in the ring.
    t_ns : ndarray of int64, shape (P,)
        Transmit time, GPS ns.
    pulse_id : ndarray of int64, shape (P,)
        Running pulse number given by the producer.
    channel : ndarray of int32, shape (P,)
        Receive channel (VITA 49 stream ID).
    flags : ndarray of uint32, shape (P,)
        :class:`~sarmoco.store.flags.PulseFlag` bits.
    """

    samples: npt.NDArray[np.generic]
    t_ns: IntArray
    pulse_id: IntArray
    channel: npt.NDArray[np.int32]
    flags: npt.NDArray[np.uint32]

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def complex_samples(self) -> npt.NDArray[np.complex64]:
        """The samples as complex64 ``(P, S)`` (int16 I/Q converted, in ADC counts)."""
        return to_complex64(self.samples)


class EchoRing:
    """Bounded ring of pulses with per-pulse time, id, channel and flags.

    All memory is allocated here, once, and written: the kernel maps a fresh page on its
    first write (a page fault, the page zeroed), which would otherwise fall on the
    producer's decode the first time round the ring (seconds of pulses at a high PRF: about
    30 µs of system CPU per 16 KiB pulse measured on a virtual machine, where the
    copy itself costs 2 µs).

    Parameters
    ----------
    capacity : int
        Number of pulse slots.
    n_samples : int
        Complex samples per pulse.
    sample_format : {"complex64", "int16"}
        Sample storage (:data:`SampleFormat`).

    Attributes
    ----------
    dropped : int
        Pulses read while the ring was full and discarded (:meth:`note_dropped`).
    duplicates, reordered, late_dropped : int
        Committed pulses discarded as duplicates, put back in time order, and
        discarded as too late (module doc).
    committed_total, aborted_total, popped_total : int
        Running counts of committed pulses, slots given back by :meth:`abort`, and
        consumed pulses.
    """

    def __init__(
        self, capacity: int, n_samples: int, sample_format: SampleFormat = "complex64"
    ) -> None:
        if capacity < 1 or n_samples < 1:
            raise ProcessingError(
                f"EchoRing: capacity {capacity} and n_samples {n_samples} must be >= 1"
            )
        if sample_format not in ("complex64", "int16"):
            raise ProcessingError(
                f"EchoRing: sample_format {sample_format!r} is not complex64 or int16"
            )
        self.capacity = capacity
        self.n_samples = n_samples
        self.sample_format: SampleFormat = sample_format
        self._samples = np.empty(
            (capacity, *sample_shape(n_samples, sample_format)), dtype=sample_dtype(sample_format)
        )
        self._samples.fill(0)  # every page written now, not on the producer's first write
        self._t_ns = np.zeros(capacity, dtype=np.int64)
        self._pulse_id = np.zeros(capacity, dtype=np.int64)
        self._channel = np.zeros(capacity, dtype=np.int32)
        self._flags = np.zeros(capacity, dtype=FLAG_DTYPE)
        self._state = np.full(capacity, _FREE, dtype=np.uint8)
        self._head = 0  # next seq to reserve
        self._tail = 0  # oldest seq not yet consumed
        self._span = 0  # slots from the tail that are committed or holes (none reserved)
        self._checked = 0  # of those, the first ones sorted out (in time order, no repeats)
        self._ready = 0  # committed pulses among the checked slots
        self._newest_ns: int | None = None  # newest pulse time checked (waiting or taken)
        self._taken_ns: int | None = None  # time of the last pulse taken
        self._drop_pending = False
        self._lock = threading.Lock()
        self.dropped = 0
        self.duplicates = 0
        self.reordered = 0
        self.late_dropped = 0
        self.committed_total = 0
        self.aborted_total = 0
        self.popped_total = 0
        self._handed: list[npt.NDArray[np.generic]] = []
        """Arrays of samples handed out by :meth:`pop`, to be reused once free (:meth:`_spare`)."""

    def reserve_block(self, max_n: int) -> Block | None:
        """Reserve up to ``max_n`` contiguous slots; ``None`` when the ring is full.

        Fewer are given when fewer are free or the ring's end comes first. A full
        ring counts no drop by itself: the producer calls :meth:`note_dropped` for
        the packets it actually discards.
        """
        with self._lock:
            free = self.capacity - (self._head - self._tail)
            if free <= 0 or max_n < 1:
                return None
            start = self._head % self.capacity
            n = min(max_n, free, self.capacity - start)
            seq = self._head
            self._head += n
            self._state[start : start + n] = _RESERVED
        return Block(seq, self._samples[start : start + n])

    def reserve(self) -> Slot | None:
        """Reserve the next slot for one pulse; ``None`` when the ring is full."""
        block = self.reserve_block(1)
        return None if block is None else Slot(block.seq, block.samples[0])

    def note_dropped(self, n: int) -> None:
        """Count ``n`` pulses read while the ring was full and discarded.

        The next committed pulse carries
        :attr:`~sarmoco.store.flags.PulseFlag.DROPPED_BEFORE`.
        """
        if n <= 0:
            return
        with self._lock:
            self.dropped += n
            self._drop_pending = True

    def commit(
        self, slot: Slot, t_ns: int, pulse_id: int, channel: int = 0, flags: int = PulseFlag.NONE
    ) -> None:
        """Publish a filled slot with its metadata.

        Parameters
        ----------
        slot : Slot
            From :meth:`reserve`, its samples written.
        t_ns : int
            Transmit time, GPS ns.
        pulse_id : int
            Running pulse number.
        channel : int
            Receive channel.
        flags : int
            :class:`~sarmoco.store.flags.PulseFlag` bits known at decode time.
        """
        i = self._check(slot.seq, 1)
        self._t_ns[i] = t_ns
        self._pulse_id[i] = pulse_id
        self._channel[i] = channel
        self._flags[i] = flags
        with self._lock:
            self._publish(slot.seq, 1, 1)

    def commit_block(
        self,
        block: Block,
        t_ns: npt.ArrayLike,
        pulse_id: npt.ArrayLike,
        channel: npt.ArrayLike,
        flags: npt.ArrayLike,
    ) -> None:
        """Publish the first ``n = len(t_ns)`` rows of a block; give the rest back.

        Parameters
        ----------
        block : Block
            From :meth:`reserve_block`, rows ``0 .. n-1`` written.
        t_ns, pulse_id : array_like of int, shape (n,)
            Transmit times (GPS ns) and running pulse numbers.
        channel, flags : array_like of int, shape (n,)
            Receive channels and :class:`~sarmoco.store.flags.PulseFlag` bits.

        Raises
        ------
        ProcessingError
            If the block is not reserved or ``n`` exceeds its length.
        """
        t = np.asarray(t_ns, dtype=np.int64)
        n = int(t.shape[0])
        i = self._check(block.seq, len(block))
        if n > len(block):
            raise ProcessingError(f"EchoRing: {n} pulses committed to a block of {len(block)}")
        rows = slice(i, i + n)
        self._t_ns[rows] = t
        self._pulse_id[rows] = pulse_id
        self._channel[rows] = channel
        self._flags[rows] = flags
        with self._lock:
            self._publish(block.seq, n, len(block))

    def abort(self, slot: Slot) -> None:
        """Give a reserved slot back unpublished (the decoder rejected the packet)."""
        self._check(slot.seq, 1)
        with self._lock:
            self.aborted_total += 1
            self._publish(slot.seq, 0, 1)

    def _publish(self, seq: int, n: int, reserved: int) -> None:
        """Mark ``n`` slots from ``seq`` committed and give back the rest (lock held).

        The first committed slot takes a pending drop flag. Slots given back at the
        head are simply unreserved; others are marked aborted and freed when they
        reach the tail.
        """
        i = seq % self.capacity
        if n:
            if self._drop_pending:
                self._flags[i] |= PulseFlag.DROPPED_BEFORE
                self._drop_pending = False
            self._state[i : i + n] = _COMMITTED
            self.committed_total += n
        if n < reserved:
            if seq + reserved == self._head:
                self._head = seq + n
                self._state[i + n : i + reserved] = _FREE
            else:
                self._state[i + n : i + reserved] = _ABORTED
        self._advance_ready()

    @property
    def free(self) -> int:
        """Slots neither reserved nor holding a pulse not yet taken."""
        with self._lock:
            return self.capacity - (self._head - self._tail)

    def __len__(self) -> int:
        """Committed pulses ready to be taken, in time order (consumer: sorts them out)."""
        with self._lock:
            self._sort_out()
            return self._ready

    def peek_times(self, max_n: int | None = None) -> IntArray:
        """Transmit times (GPS ns) of the ready pulses, oldest first (a copy).

        Parameters
        ----------
        max_n : int, optional
            Look at no more than this many pulses.
        """
        with self._lock:
            self._sort_out()
            n = self._ready if max_n is None else min(max_n, self._ready)
            idx, _ = self._indices(n)
            return self._t_ns[idx].copy()

    def pop(self, n: int) -> EchoBatch:
        """Take the ``n`` oldest ready pulses out of the ring (copied, slots freed).

        The pulses are those a look (``len``, :meth:`peek_times`) saw first; new ones
        are sorted out only when fewer than ``n`` were seen. The samples are copied into
        an array of an earlier pop of ``n`` pulses that nothing refers to any more, when
        there is one (:meth:`_spare`): pops of one size touch no fresh memory.

        Raises
        ------
        ProcessingError
            If fewer than ``n`` pulses are ready.
        """
        with self._lock:
            if n > self._ready:
                self._sort_out()
            if n > self._ready:
                raise ProcessingError(f"EchoRing.pop: {n} pulses asked, {self._ready} ready")
            idx, used = self._indices(n)
        batch = EchoBatch(
            # mode "clip" (the positions are in range): "raise" would copy through a buffer
            samples=np.take(self._samples, idx, axis=0, out=self._spare(n), mode="clip"),
            t_ns=self._t_ns[idx],
            pulse_id=self._pulse_id[idx],
            channel=self._channel[idx],
            flags=self._flags[idx],
        )
        with self._lock:
            self._state[self._positions(self._tail, used)] = _FREE
            self._tail += used
            self._span -= used
            self._checked -= used
            self._ready -= n
            self.popped_total += n
            if n:
                self._taken_ns = int(batch.t_ns[-1])
            self._advance_ready()
        return batch

    def _spare(self, n: int) -> npt.NDArray[np.generic]:
        """An array for the samples of ``n`` popped pulses (consumer thread).

        Every array a pop handed out is kept in :attr:`_handed`; one that nothing else
        refers to any more (CPython's reference count: a view of it counts) is free. The
        first free one of ``n`` rows is reused (its pages written already: a fresh array
        costs a page fault per 4 KiB at its first write); free ones of other sizes met on
        the way are let go. None free: a new array. Arrays come back about in the order
        they were handed out (focusing takes the oldest pulses, skipping drops the oldest
        not looked at), so the look is short.
        """
        handed, i = self._handed, 0
        while i < len(handed):
            arr = handed[i]
            if sys.getrefcount(arr) > _HELD_BY_POOL:  # in use
                i += 1
            elif handed.pop(i).shape[0] == n:
                break  # free and of the size: reused
        else:
            arr = np.empty((n, *self._samples.shape[1:]), self._samples.dtype)
        handed.append(arr)
        return arr

    def _indices(self, n: int) -> tuple[npt.NDArray[np.intp], int]:
        """Ring positions of the first ``n`` ready pulses, and the slots up to the last
        of them (holes included) from the tail (lock held)."""
        pos = self._positions(self._tail, self._checked)
        if self._ready < self._checked:  # holes among them
            pos = pos[self._state[pos] == _COMMITTED]
        idx = pos[:n]
        used = 0 if n == 0 else int((idx[-1] - self._tail) % self.capacity) + 1
        return idx, used

    def _advance_ready(self) -> None:
        """Extend the span over newly committed slots and holes; free holes at the tail
        (lock held)."""
        start = self._tail + self._span
        states = self._states(start, self._head - start)
        n = _leading(states >= _COMMITTED)  # committed slots and holes, up to a reserved one
        if self._span == 0:  # holes at the tail are freed at once
            holes = _leading(states[:n] == _ABORTED)
            self._state[self._positions(self._tail, holes)] = _FREE
            self._tail += holes
            n -= holes
        self._span += n

    def _sort_out(self) -> None:
        """Check the span's new slots: keep, put back in order, or discard (module doc;
        lock held, consumer thread only: the rows moved belong to no producer).

        Pulses newer than the one before them, as a radar sends them, are taken a run at a
        time (:data:`SORT_RUN`); a slot that breaks the run is sorted out on its own."""
        while self._checked < self._span:
            n = self._in_order_run()
            if n:
                self._checked += n
                self._ready += n
                self._newest_ns = int(self._t_ns[(self._tail + self._checked - 1) % self.capacity])
            else:
                self._sort_out_one()

    def _in_order_run(self) -> int:
        """How many of the span's next slots (up to :data:`SORT_RUN`) are committed pulses
        each newer than the one before, the first newer than every pulse checked (lock held)."""
        pos = self._positions(self._tail + self._checked, min(self._span - self._checked, SORT_RUN))
        t = self._t_ns[pos]
        newer = np.empty(t.shape, bool)
        newer[0] = self._newest_ns is None or t[0] > self._newest_ns
        np.greater(t[1:], t[:-1], out=newer[1:])
        return _leading(newer & (self._state[pos] == _COMMITTED))

    def _sort_out_one(self) -> None:
        """Check the span's next slot alone: a hole, a pulse not newer than every one checked
        (a duplicate, late, or put back in order), or a pulse in order (lock held)."""
        off = self._checked
        i = (self._tail + off) % self.capacity
        self._checked += 1
        if self._state[i] != _COMMITTED:
            return
        t = int(self._t_ns[i])
        if self._newest_ns is None or t > self._newest_ns:
            self._newest_ns = t
            self._ready += 1
            return
        if self._taken_ns is not None and t <= self._taken_ns:
            self._discard(i, duplicate=t == self._taken_ns)
            return
        lo = max(0, off - REORDER_WINDOW)
        pos = self._positions(self._tail + lo, off - lo)
        pos = pos[self._state[pos] == _COMMITTED]
        times = self._t_ns[pos]
        k = int(np.searchsorted(times, t))
        if k < times.size and times[k] == t:
            self._discard(i, duplicate=True)
        elif k == 0 and self._ready > pos.size:  # its place is further back
            self._discard(i, duplicate=False)
        else:
            self._move_back(int((pos[k] - self._tail) % self.capacity), off)
            self.reordered += 1
            self._ready += 1

    def _positions(self, seq: int, n: int) -> npt.NDArray[np.intp]:
        """Ring positions of the ``n`` slots from reservation number ``seq`` on."""
        return (seq + np.arange(n)) % self.capacity

    def _states(self, seq: int, n: int) -> npt.NDArray[np.uint8]:
        """States of the ``n`` slots from reservation number ``seq`` on (a view where they
        do not wrap around the ring's end)."""
        i = seq % self.capacity
        if i + n <= self.capacity:
            return self._state[i : i + n]
        return np.concatenate((self._state[i:], self._state[: i + n - self.capacity]))

    def _discard(self, i: int, duplicate: bool) -> None:
        """Make the committed slot ``i`` a hole, counted as a duplicate or late (lock held)."""
        self._state[i] = _ABORTED
        if duplicate:
            self.duplicates += 1
        else:
            self.late_dropped += 1

    def _move_back(self, to: int, off: int) -> None:
        """Move the slot at span offset ``off`` to offset ``to``; those between move up one."""
        pos = self._positions(self._tail + to, off + 1 - to)
        src = np.roll(pos, 1)
        for arr in (self._samples, self._t_ns, self._pulse_id, self._channel, self._flags,
                    self._state):  # fmt: skip
            arr[pos] = arr[src]

    def _check(self, seq: int, n: int) -> int:
        """Ring position of ``n`` reserved slots from ``seq``; raises if any is not reserved."""
        i = seq % self.capacity
        if not self._tail <= seq <= self._head - n or (self._state[i : i + n] != _RESERVED).any():
            raise ProcessingError(f"EchoRing: slots {seq}..{seq + n - 1} are not reserved")
        return int(i)


def _leading(mask: npt.NDArray[np.bool_]) -> int:
    """How many elements at the start of ``mask`` are True."""
    return int(mask.size if mask.all() else np.argmin(mask))
