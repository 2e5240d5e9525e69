"""The simulated SBG INS: sbgECom binary logs over a pseudo-terminal or into a file.

Per INS sample: EKF_NAV (velocity NED, geodetic position: the INS position, or the
velocity integrated from the true position at the first sample for grades without
one; NED about :data:`~sarmoco.sim.insfeed.GEODETIC_ORIGIN`, position valid; the altitude
above mean sea level with the geoid undulation :data:`~sarmoco.sim.insfeed.GEOID_UNDULATION_M`)
and EKF_QUAT (or
EKF_EULER); every ``utc_period_s`` a UTC_TIME pairing the device clock with UTC
and the GPS time of week; one EVENT_A per radar pulse (sync-in: the pulse
transmit time on the device clock). Times are the device clock in µs since
power-up (:class:`~sarmoco.sim.insclock.InsClock`). Frames come from the
drivers' encoder (:func:`sarmoco.drivers.sbg_codec.encode_message`).
"""

from __future__ import annotations

import datetime as dt
from abc import abstractmethod
from collections.abc import Iterator
from functools import partial
from typing import Any, Literal

import numpy as np

from sarmoco.drivers import sbg_codec as codec
from sarmoco.drivers.attitude import quat_to_euler
from sarmoco.drivers.clock import NS_PER_S, SECONDS_PER_WEEK
from sarmoco.geodesy import ned_to_geodetic
from sarmoco.processing.types import FloatArray
from sarmoco.sim.emit_mavlink import dead_reckoned
from sarmoco.sim.emitter import Emitter
from sarmoco.sim.faults import PacketFaults
from sarmoco.sim.insfeed import GEODETIC_ORIGIN, GEOID_UNDULATION_M, InsFeed
from sarmoco.sim.pacing import Event, merge
from sarmoco.sim.transports import Link

SOLUTION_NAV_POSITION = 4
"""sbgECom solution mode "full navigation" (bits 0-3 of the EKF status)."""
UTC_STATUS = (codec.CLOCK_VALID << codec.CLOCK_STATE_SHIFT) | (
    codec.UTC_INITIALIZED << codec.UTC_STATUS_SHIFT
)
"""UTC_TIME status of a device synchronised to GPS with valid leap seconds."""
MIN_STD = 1e-4
"""Floor of the accuracies reported (an ideal INS still reports a non-zero sigma)."""


def utc_fields(unix_ns: int) -> tuple[int, int, int, int, int, int, int]:
    """POSIX ns → (year, month, day, hour, minute, second, nanosecond) in UTC."""
    seconds, ns = divmod(unix_ns, NS_PER_S)
    d = dt.datetime.fromtimestamp(seconds, dt.UTC)
    return d.year, d.month, d.day, d.hour, d.minute, d.second, ns


def vec3(a: FloatArray) -> tuple[float, float, float]:
    """Three floats of an array row."""
    return float(a[0]), float(a[1]), float(a[2])


def vec4(a: FloatArray) -> tuple[float, float, float, float]:
    """Four floats of an array row."""
    return float(a[0]), float(a[1]), float(a[2]), float(a[3])


def gps_tow_ms(gps_ns: int) -> int:
    """GPS time of week of a GPS time, ms (truncated)."""
    return (gps_ns % (SECONDS_PER_WEEK * NS_PER_S)) // 1_000_000


class SbgDevice(Emitter):
    """What the SBG INS does on every link: samples, time references and pulse events.

    Parameters
    ----------
    link : Link
        Where the frames go.
    feed : InsFeed
        Samples, device clock and pulse events.
    attitude : {"quat", "euler"}
        Attitude as a quaternion or as Euler angles.
    utc_period_s : float
        Interval between time references, s.
    events : bool
        Send a pulse event (sync-in) per radar pulse.
    faults, seed, rank
        See :class:`~sarmoco.sim.emitter.Emitter`.
    """

    def __init__(
        self,
        link: Link,
        feed: InsFeed,
        *,
        attitude: Literal["quat", "euler"] = "quat",
        utc_period_s: float = 0.2,
        events: bool = True,
        faults: PacketFaults | None = None,
        seed: int = 0,
        rank: int = 1,
    ) -> None:
        super().__init__(link, faults, seed, rank)
        self.feed = feed
        self.attitude = attitude
        self.utc_every = feed.every(utc_period_s)
        self.with_events = events

    def _samples(self) -> Iterator[Event]:
        """One event per INS sample, after the output latency."""
        f = self.feed
        return (
            Event(int(f.t_ns[i]) + f.latency_ns, self.rank, partial(self._sample, i))
            for i in range(f.t_ns.size)
        )

    def _pulse_events(self) -> Iterator[Event]:
        """One event per radar pulse, after the output latency."""
        f = self.feed
        return (
            Event(int(t) + f.latency_ns, self.rank, partial(self._event, int(t)))
            for t in f.pulse_t_ns
        )

    @abstractmethod
    def _sample(self, i: int) -> None:
        """Send the frames of INS sample ``i``."""

    @abstractmethod
    def _event(self, t_pulse_ns: int) -> None:
        """Send the pulse event of a pulse transmitted at ``t_pulse_ns`` (scenario GPS ns)."""


class SbgEmitter(SbgDevice):
    """Plays a run's INS samples as sbgECom logs (EKF_QUAT or EKF_EULER, UTC_TIME, EVENT_A).

    Parameters
    ----------
    link, feed, attitude, utc_period_s, events, faults, seed, rank
        See :class:`SbgDevice` (link: a pseudo-terminal or a file, frames back to back).
    """

    protocol = "sbgecom"

    def __init__(self, link: Link, feed: InsFeed, **options: Any) -> None:
        super().__init__(link, feed, **options)
        pos_ned = (
            feed.pos_ned
            if feed.pos_ned is not None
            else feed.start_pos_ned + dead_reckoned(feed.t_ns, feed.vel_ned)
        )
        self.geodetic = ned_to_geodetic(pos_ned, GEODETIC_ORIGIN)
        self.geodetic[:, 2] -= GEOID_UNDULATION_M  # EKF_NAV's altitude is above mean sea level
        g = feed.grade
        self.vel_std = vec3(np.full(3, max(g.vel_std_mps, MIN_STD)))
        self.att_std = vec3(np.full(3, max(g.att_std_rad, MIN_STD)))
        self.pos_std = vec3(np.full(3, max(g.pos_noise_m, MIN_STD)))
        self.status = SOLUTION_NAV_POSITION | codec.SOL_ATTITUDE_VALID | codec.SOL_HEADING_VALID
        self.status |= codec.SOL_VELOCITY_VALID | codec.SOL_POSITION_VALID
        self.sent: dict[str, int] = {"EKF_NAV": 0, "EKF_ATT": 0, "UTC_TIME": 0, "EVENT_A": 0}

    def events(self) -> Iterator[Event]:
        """Samples (UTC_TIME first when due) and pulse events, each after the output latency."""
        if not self.with_events:
            return self._samples()
        return merge([self._samples(), self._pulse_events()])

    def _send_msg(self, msg: codec.Message, name: str, t_ns: int) -> None:
        self.sent[name] += 1
        self.send(codec.encode_message(msg), t_ns)

    def _sample(self, i: int) -> None:
        f = self.feed
        t_emit = int(f.t_ns[i]) + f.latency_ns
        up_ns = int(f.uptime_ns[i])
        time_us = round(up_ns / 1000)
        if f.index[i] % self.utc_every == 0:
            # the GPS instant at which the device clock reads time_us exactly
            t_ref = int(f.t_ns[i]) + time_us * 1000 - up_ns
            utc_f = utc_fields(self.wire.unix_ns(t_ref))
            utc = codec.UtcTime(time_us, UTC_STATUS, *utc_f, gps_tow_ms(self.wire.gps_ns(t_ref)))
            self._send_msg(utc, "UTC_TIME", t_emit)
        q = vec4(f.quat[i])
        lla = vec3(self.geodetic[i])
        status = self.status
        nav = codec.EkfNav(
            time_us, vec3(f.vel_ned[i]), self.vel_std, lla, GEOID_UNDULATION_M, self.pos_std,
            status,
        )  # fmt: skip
        self._send_msg(nav, "EKF_NAV", t_emit)
        att: codec.Message
        if self.attitude == "quat":
            att = codec.EkfQuat(time_us, q, self.att_std, status)
        else:
            att = codec.EkfEuler(time_us, quat_to_euler(q), self.att_std, status)
        self._send_msg(att, "EKF_ATT", t_emit)

    def _event(self, t_pulse_ns: int) -> None:
        time_us = round(self.feed.clock.uptime_ns(t_pulse_ns) / 1000)
        msg = codec.Event(time_us, 0, (0, 0, 0, 0))
        self._send_msg(msg, "EVENT_A", t_pulse_ns + self.feed.latency_ns)

    def connect_hint(self) -> dict[str, Any]:
        return {
            "connect": self.link.describe().get("path"),
            "geodetic_origin": list(GEODETIC_ORIGIN),
        }

    def stats(self) -> dict[str, Any]:
        return {**super().stats(), "messages": dict(self.sent)}
