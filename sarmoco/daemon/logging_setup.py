"""Structured logs: one line per event on stderr (journald) or in a file.

Each record becomes one line, either a JSON object or ``key=value`` pairs,
with the time (UTC, ISO 8601), level, logger and message, plus every field
passed with ``extra=`` (``log.info("block recorded", extra={"pulses": 256})``)
and the traceback of an exception, escaped onto the same line. Under systemd
stderr goes to the journal; with a log file, :func:`reopen_logs` (wired to
SIGHUP by :func:`install_sighup`) reopens it after logrotate moved it.
"""

from __future__ import annotations

import datetime
import json
import logging
import signal
import sys
from pathlib import Path
from types import FrameType
from typing import Any, Literal, TextIO

LogFormat = Literal["json", "kv"]

_STANDARD_ATTRS = frozenset(vars(logging.makeLogRecord({}))) | {"message", "asctime"}


def _fields(record: logging.LogRecord) -> dict[str, Any]:
    out: dict[str, Any] = {
        "ts": datetime.datetime.fromtimestamp(record.created, datetime.UTC).isoformat(
            timespec="microseconds"
        ),
        "level": record.levelname.lower(),
        "logger": record.name,
        "msg": record.getMessage(),
    }
    for key, value in vars(record).items():
        if key not in _STANDARD_ATTRS and not key.startswith("_"):
            out[key] = value
    if record.exc_info:
        out["exc"] = logging.Formatter().formatException(record.exc_info)
    return out


class JsonFormatter(logging.Formatter):
    """One JSON object per record (non-JSON values are written with ``str``)."""

    def format(self, record: logging.LogRecord) -> str:
        return json.dumps(_fields(record), default=str)


class KeyValueFormatter(logging.Formatter):
    """``key=value`` pairs per record; values with spaces, quotes or ``=`` are JSON-quoted."""

    def format(self, record: logging.LogRecord) -> str:
        parts = []
        for key, value in _fields(record).items():
            text = value if isinstance(value, str) else json.dumps(value, default=str)
            if not text or any(c in text for c in ' "=\n\t\\'):
                text = json.dumps(text)
            parts.append(f"{key}={text}")
        return " ".join(parts)


class ReopenableFileHandler(logging.StreamHandler[TextIO]):
    """Appends to a file that :meth:`reopen` opens again (after log rotation)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        super().__init__(self.path.open("a", encoding="utf-8"))

    def reopen(self) -> None:
        """Close the file and open ``path`` again (creating it if it was moved away)."""
        self.acquire()
        try:
            self.flush()
            self.stream.close()
            self.stream = self.path.open("a", encoding="utf-8")
        finally:
            self.release()

    def close(self) -> None:
        self.acquire()
        try:
            self.stream.close()
        finally:
            self.release()
        super().close()


_handler: logging.Handler | None = None


def setup_logging(
    level: str = "info",
    fmt: LogFormat = "json",
    path: str | Path | None = None,
    stream: TextIO | None = None,
) -> logging.Handler:
    """Send every log record of the process, one line each, to stderr or a file.

    Parameters
    ----------
    level : str
        ``debug``, ``info``, ``warning`` or ``error``.
    fmt : {"json", "kv"}
        Line format.
    path : str or Path, optional
        Log file (reopened by :func:`reopen_logs`); default stderr.
    stream : file, optional
        Write here instead of stderr (tests).

    Returns
    -------
    logging.Handler
        The handler installed on the root logger (replacing the previous one
        installed here).
    """
    global _handler
    handler: logging.Handler = (
        ReopenableFileHandler(path)
        if path is not None
        else logging.StreamHandler(stream if stream is not None else sys.stderr)
    )
    handler.setFormatter(JsonFormatter() if fmt == "json" else KeyValueFormatter())
    root = logging.getLogger()
    if _handler is not None:
        root.removeHandler(_handler)
        _handler.close()
    root.addHandler(handler)
    root.setLevel(level.upper())
    _handler = handler
    return handler


def reopen_logs() -> None:
    """Reopen the log file, if logs go to one (nothing to do for stderr)."""
    if isinstance(_handler, ReopenableFileHandler):
        _handler.reopen()


def install_sighup() -> None:
    """Reopen the logs on SIGHUP (call from the main thread)."""

    def on_hup(signum: int, frame: FrameType | None) -> None:
        reopen_logs()

    signal.signal(signal.SIGHUP, on_hup)
