"""Store writes on a thread of their own, in the order they were handed over.

The processing loop hands each write (a function and its arguments) to an
:class:`OrderedWriter` and goes on; one writer thread runs them one after the
other, exactly in that order, so every guarantee a sequence of writes gives on one
thread (rows before ``committed``, fsync every interval) holds unchanged. The
queue is bounded: when the disk falls behind by ``depth`` writes, handing over the
next one blocks (back-pressure reaches the processing loop, and from there the echo
ring, as a slow disk did before). The first write that fails stops the thread's
work: the writes after it are dropped, and every later call re-raises the failure
as a :class:`~sarmoco.errors.RecorderError`. A failure that comes after the caller's
last call is there to see without a call (:attr:`OrderedWriter.failure`): the
caller's health check looks at it.

With ``depth = 0`` there is no thread: each write runs at once on the caller's
thread (what the recorder did before, and what tests and batch tools use).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any

from sarmoco.closing import Closing
from sarmoco.errors import RecorderError

_STOP = None
"""Queue item that ends the writer thread."""


class OrderedWriter(Closing):
    """Run write functions on one thread in the order they were submitted.

    Parameters
    ----------
    name : str
        Name of the thread (for logs and debuggers).
    depth : int
        Writes that may wait in the queue (>= 0); 0: run each write at once on the
        caller's thread.
    on_failure : callable, optional
        Called (no arguments, on the thread of the write) when a write fails, before
        the failure is raised or kept: to let what the write left running end.
    """

    def __init__(self, name: str, depth: int, on_failure: Callable[[], None] | None = None) -> None:
        if depth < 0:
            raise RecorderError(f"recorder writer: queue depth {depth!r} is not >= 0")
        self.depth = depth
        self._on_failure = on_failure
        self._error: BaseException | None = None
        """The writer thread's first failure (the writes after it are dropped)."""
        self._last_error: BaseException | None = None
        """The failure of the last write run, None if it succeeded."""
        self._queue: queue.Queue[tuple[Callable[..., Any], tuple[Any, ...]] | None] = queue.Queue(
            maxsize=depth
        )
        self._thread: threading.Thread | None = None
        if depth > 0:
            self._thread = threading.Thread(target=self._run, name=name, daemon=True)
            self._thread.start()

    @property
    def threaded(self) -> bool:
        """Whether writes run on the writer thread (and must not share mutable arguments)."""
        return self._thread is not None

    def submit(self, write: Callable[..., Any], *args: Any) -> None:
        """Hand over ``write(*args)``: queued (blocks while the queue is full), or run now.

        Raises
        ------
        RecorderError
            An earlier write failed (that failure), or the writer is closed.
        """
        self.raise_error()
        if self._thread is None:
            self._run_one(write, args)
            return
        if not self._thread.is_alive():
            raise RecorderError("recorder writer: closed")
        self._queue.put((write, args))

    def drain(self) -> None:
        """Wait until every write handed over has run (not when called by one of them, on
        the writer thread); re-raise a failure."""
        if self._thread is not None and threading.current_thread() is not self._thread:
            self._queue.join()
        self.raise_error()

    @property
    def failure(self) -> RecorderError | None:
        """The failure that stands, as a RecorderError (None: none).

        With the thread, its first failure: no write runs after it. Without, the last
        write's, until a write succeeds (the caller's call raised it).
        """
        return _recorder_error(self._error if self._thread is not None else self._last_error)

    def raise_error(self) -> None:
        """Raise the first failure of a queued write, if any, as a RecorderError."""
        failure = _recorder_error(self._error)
        if failure is not None:
            raise failure

    def close(self) -> None:
        """Run the writes still queued, then end the thread (failures stay for :meth:`drain`)."""
        if self._thread is None:
            return
        if self._thread.is_alive():
            self._queue.put(_STOP)
            self._thread.join()

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            try:
                if item is _STOP:
                    return
                if self._error is None:
                    self._run_one(*item)
            except BaseException as exc:  # handed to the caller by raise_error
                self._error = exc
            finally:
                self._queue.task_done()

    def _run_one(self, write: Callable[..., Any], args: tuple[Any, ...]) -> None:
        """``write(*args)``; ``on_failure()`` first if it raises."""
        try:
            write(*args)
        except BaseException as exc:
            self._last_error = exc
            if self._on_failure is not None:
                self._on_failure()
            raise
        self._last_error = None


def _recorder_error(err: BaseException | None) -> RecorderError | None:
    """``err`` as the RecorderError the writer's callers get (caused by ``err``)."""
    if err is None:
        return None
    failure = RecorderError(f"{err}" if isinstance(err, RecorderError) else repr(err))
    failure.__cause__ = err
    return failure
