"""GPS and UTC epochs and the conversions between them.

The one time base of sarmoco is **GPS time in integer nanoseconds since the GPS
epoch** (1980-01-06T00:00:00, GPS time scale: continuous, no leap seconds).
UTC values enter as POSIX time (seconds since 1970-01-01T00:00:00 UTC, leap
seconds not counted, as ``time.time()`` and VITA 49 "UTC" timestamps count
them). GPS − UTC is a whole number of leap seconds (18 s since 2017-01-01),
which is configuration, never hard-wired into a conversion.
"""

from __future__ import annotations

import calendar

from sarmoco.errors import ClockError

NS_PER_S = 1_000_000_000
GPS_EPOCH_UNIX_S = 315_964_800
"""POSIX seconds of the GPS epoch 1980-01-06T00:00:00 UTC (no leap seconds then)."""
GPS_LEAP_SECONDS_DEFAULT = 18
"""GPS − UTC in seconds, valid since 2017-01-01."""
SECONDS_PER_WEEK = 604_800


def unix_ns_to_gps_ns(unix_ns: int, leap_s: int = GPS_LEAP_SECONDS_DEFAULT) -> int:
    """POSIX UTC time (ns since 1970) → GPS time (ns since 1980-01-06), adding ``leap_s``."""
    return int(unix_ns) - GPS_EPOCH_UNIX_S * NS_PER_S + int(leap_s) * NS_PER_S


def gps_ns_to_unix_ns(gps_ns: int, leap_s: int = GPS_LEAP_SECONDS_DEFAULT) -> int:
    """GPS time (ns since 1980-01-06) → POSIX UTC time (ns since 1970), removing ``leap_s``."""
    return int(gps_ns) + GPS_EPOCH_UNIX_S * NS_PER_S - int(leap_s) * NS_PER_S


def gps_week_ms_to_gps_ns(week: int, tow_ms: int) -> int:
    """GPS week number and time of week (ms) → GPS ns."""
    return (int(week) * SECONDS_PER_WEEK * 1000 + int(tow_ms)) * 1_000_000


def utc_calendar_to_unix_ns(
    year: int, month: int, day: int, hour: int, minute: int, second: int, nanosecond: int
) -> int:
    """A UTC calendar date and time → POSIX ns.

    Raises
    ------
    ClockError
        If a field is out of range (the device has no valid date yet, or the bytes are damaged).
    """
    if not (
        1980 <= year <= 2200
        and 1 <= month <= 12
        and 1 <= day <= 31
        and 0 <= hour <= 23
        and 0 <= minute <= 59
        and 0 <= second <= 60
        and -NS_PER_S < nanosecond < NS_PER_S
    ):
        raise ClockError(
            f"UTC date {year:04d}-{month:02d}-{day:02d} {hour:02d}:{minute:02d}:{second:02d}"
            f" +{nanosecond} ns is not a valid time"
        )
    seconds = calendar.timegm((year, month, day, hour, minute, second, 0, 0, 0))
    return seconds * NS_PER_S + nanosecond


def gps_ns_from_tow(tow_ms: int, near_gps_ns: int) -> int:
    """Resolve a GPS time of week (ms) to full GPS ns using a time known to within half a week.

    Parameters
    ----------
    tow_ms : int
        GPS time of week, ms.
    near_gps_ns : int
        Any GPS time within ±3.5 days of the answer (e.g. from the UTC date), ns.
    """
    week_ns = SECONDS_PER_WEEK * NS_PER_S
    week = round((near_gps_ns - tow_ms * 1_000_000) / week_ns)
    return week * week_ns + tow_ms * 1_000_000
