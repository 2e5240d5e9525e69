"""The one exception tree of sarmoco.

Every error raised on purpose by sarmoco derives from :class:`SarmocoError`.
Where a builtin exception has the same meaning, the family inherits it too,
so ``except ValueError`` in calling code keeps working (the python-can model).
"""

from __future__ import annotations


class SarmocoError(Exception):
    """Root of every error raised by sarmoco."""


class ConfigError(SarmocoError, ValueError):
    """A configuration value is missing, of the wrong type or out of range.

    The message always names the key path, the bad value and what is allowed,
    e.g. ``radar.prf_hz: -3 is not > 0``.
    """


class ProtocolError(SarmocoError, ValueError):
    """Bytes from a link or a log do not form a valid frame or packet."""


class ClockError(SarmocoError, ValueError):
    """A clock cannot be mapped onto GPS time (no sync yet, a step, a reboot)."""


class NavigationError(SarmocoError, ValueError):
    """Navigation data do not cover the requested time (gap, not bracketed)."""


class ProcessingError(SarmocoError, ValueError):
    """Inputs to a processing stage are inconsistent (shapes, units, geometry)."""


class RecorderError(SarmocoError, OSError):
    """The recording store cannot be created, written or read."""


class DriverError(SarmocoError, OSError):
    """A link (socket, serial port, CAN bus, file) cannot be opened or used."""


class DataFileError(SarmocoError, ValueError):
    """A data file (phase history, flight log) is missing fields or malformed."""
