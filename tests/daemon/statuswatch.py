"""A live daemon's ``/status`` as the tests read it: once, or every read of a whole run."""

from __future__ import annotations

import json
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


def read_status(port: int) -> dict[str, Any] | None:
    """``GET /status`` on 127.0.0.1:``port``; None when it does not answer (yet)."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1.0) as s:
            s.sendall(b"GET /status HTTP/1.0\r\nHost: x\r\n\r\n")
            body = b"".join(iter(lambda: s.recv(65536), b"")).split(b"\r\n\r\n", 1)
        doc: dict[str, Any] = json.loads(body[1])
        return doc
    except (OSError, ValueError, IndexError):
        return None


@contextmanager
def watching_status(port: int, period_s: float) -> Iterator[list[dict[str, Any]]]:
    """Read ``/status`` every ``period_s`` (s) on a thread while the block runs; yields the
    list the answers are appended to, in order."""
    seen: list[dict[str, Any]] = []
    done = threading.Event()

    def watch() -> None:
        while not done.wait(period_s):
            doc = read_status(port)
            if doc is not None:
                seen.append(doc)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        yield seen
    finally:
        done.set()
        watcher.join()
