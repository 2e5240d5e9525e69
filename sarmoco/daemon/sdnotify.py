"""A pure-socket client of the systemd notification protocol (sd_notify(3)).

No libsystemd: a datagram is sent on the AF_UNIX socket named by
``NOTIFY_SOCKET`` (a filesystem path, or an abstract name written ``@name``).
When the variable is unset (not started by systemd) every call is a no-op.
"""

from __future__ import annotations

import math
import os
import socket
import time
from collections.abc import Mapping

from sarmoco.errors import DriverError


class Notifier:
    """Send READY/STATUS/WATCHDOG/STOPPING messages to the service manager.

    Parameters
    ----------
    environ : mapping, optional
        Where to read ``NOTIFY_SOCKET``, ``WATCHDOG_USEC`` and ``WATCHDOG_PID``
        (default: ``os.environ``).
    """

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        name = env.get("NOTIFY_SOCKET", "")
        self._address: str | bytes | None
        if not name:
            self._address = None
        elif name.startswith("@"):
            self._address = b"\0" + name[1:].encode()
        elif name.startswith("/"):
            self._address = name
        else:
            raise DriverError(f"NOTIFY_SOCKET: {name!r} is neither a path nor an @abstract name")
        self._watchdog_s = self._parse_watchdog(env)
        self._sock: socket.socket | None = None
        self._last_keepalive_s = -math.inf

    @staticmethod
    def _parse_watchdog(env: Mapping[str, str]) -> float | None:
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        if not usec.isdigit() or int(usec) == 0:
            return None
        if pid and (not pid.isdigit() or int(pid) != os.getpid()):
            return None
        return int(usec) / 1e6

    @property
    def enabled(self) -> bool:
        """True when a notification socket is configured."""
        return self._address is not None

    @property
    def watchdog_interval_s(self) -> float | None:
        """The watchdog timeout systemd set for this process, s (None if none)."""
        return self._watchdog_s

    def notify(self, fields: Mapping[str, str | int]) -> None:
        """Send one datagram of ``KEY=value`` lines (no-op when not enabled).

        Raises
        ------
        DriverError
            If the socket exists but the datagram cannot be sent.
        """
        if self._address is None:
            return
        payload = "\n".join(f"{k}={v}" for k, v in fields.items()).encode()
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(payload, self._address)
        except OSError as exc:
            raise DriverError(f"sd_notify to {self._address!r} failed: {exc}") from exc

    def ready(self, status: str | None = None) -> None:
        """``READY=1`` (with an optional ``STATUS=``)."""
        msg: dict[str, str | int] = {"READY": 1}
        if status is not None:
            msg["STATUS"] = status
        self.notify(msg)

    def status(self, text: str) -> None:
        """``STATUS=text``: one line shown by ``systemctl status``."""
        self.notify({"STATUS": text.replace("\n", " ")})

    def watchdog(self) -> None:
        """``WATCHDOG=1``: the keep-alive ping."""
        self.notify({"WATCHDOG": 1})

    def keepalive(self, now_s: float | None = None) -> bool:
        """``WATCHDOG=1`` if systemd watches this process and half its interval has passed.

        Call it as often as convenient (every pass of a loop that is healthy): it pings
        at most once per ``WATCHDOG_USEC / 2``, as sd_watchdog_enabled(3) recommends.

        Parameters
        ----------
        now_s : float, optional
            Monotonic time, s (default ``time.monotonic()``).

        Returns
        -------
        bool
            Whether a ping was sent.
        """
        if self._watchdog_s is None or self._address is None:
            return False
        now = time.monotonic() if now_s is None else now_s
        if now - self._last_keepalive_s < self._watchdog_s / 2:
            return False
        self.watchdog()
        self._last_keepalive_s = now
        return True

    def stopping(self) -> None:
        """``STOPPING=1``: shutdown has begun."""
        self.notify({"STOPPING": 1})

    def extend_timeout(self, usec: int) -> None:
        """``EXTEND_TIMEOUT_USEC=usec``: ask for more time to start or stop."""
        self.notify({"EXTEND_TIMEOUT_USEC": int(usec)})

    def close(self) -> None:
        """Close the socket (safe to call twice)."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None
