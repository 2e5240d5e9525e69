"""Typed, timestamped samples produced by every driver.

Drivers do not depend on :mod:`sarmoco.processing`; the daemon converts these
records into its own arrays. Conventions (docs/methods.md §1): SI units, velocities in
local NED (north, east, down) m/s, quaternions scalar-first ``(w, x, y, z)``
rotating body-frame vectors into NED, times in GPS ns since 1980-01-06
(:mod:`sarmoco.drivers.clock`).
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, fields
from typing import Literal

import numpy as np
import numpy.typing as npt


class Validity(enum.IntFlag):
    """What the source says is trustworthy in a sample."""

    NONE = 0
    ATTITUDE = 1
    """Roll and pitch are valid."""
    HEADING = 2
    """Heading (yaw) is valid."""
    VELOCITY = 4
    """Velocity is valid."""
    POSITION = 8
    """Position is valid."""
    TIME = 16
    """The sample time is mapped onto GPS time by a synchronised clock."""


@dataclass(frozen=True, slots=True)
class TangentFrame:
    """A local NED frame on the Earth: north, east, down axes at a geodetic point, origin there.

    Attributes
    ----------
    lat_lon_alt : tuple of 3 float
        The point: latitude, longitude (deg, WGS 84) and altitude (m; see
        ``ellipsoid_height``).
    source : str
        What set it: the INS's own statement of its frame (``"mavlink.GPS_GLOBAL_ORIGIN"``,
        the autopilot's EKF origin) or the first valid position a driver received
        (``"sbg.EKF_NAV"``, ``"mavlink.GLOBAL_POSITION_INT"``).
    ellipsoid_height : bool
        The altitude is the height above the WGS-84 ellipsoid (an SBG INS: its altitude
        above mean sea level plus the geoid undulation it sends). False: the altitude above
        mean sea level as the INS gives it (MAVLink), used as the ellipsoid height (the
        geoid undulation, tens of metres, unknown).
    stated : bool
        The INS named this point as the origin of its positions (an EKF origin); False:
        the first position a driver received, a point of the daemon's choosing.
    """

    lat_lon_alt: tuple[float, float, float]
    source: str
    ellipsoid_height: bool = False
    stated: bool = False


@dataclass(frozen=True, slots=True)
class VelocitySample:
    """Velocity (and position when the message has one) of the INS.

    Attributes
    ----------
    t_gps_ns : int
        Sample time, GPS ns.
    vel_ned : tuple of 3 float
        Velocity north, east, down, m/s.
    valid : Validity
        Validity flags from the source's solution status.
    source : str
        Message it came from, e.g. ``"sbg.EKF_NAV"``, ``"mavlink.LOCAL_POSITION_NED"``.
    device_time_ns : int
        The same instant on the device's own clock (boot time), ns.
    pos_ned : tuple of 3 float or None
        Local NED position, m, when the message carries one (or its driver derives it
        from a geodetic one), in the frame ``pos_frame``.
    vel_std_mps : tuple of 3 float or None
        1-sigma velocity accuracy, m/s, when the message carries one.
    lat_lon_alt : tuple of 3 float or None
        Latitude, longitude (deg, WGS 84) and altitude (m: above the ellipsoid when
        ``pos_frame.ellipsoid_height``, else above mean sea level), when the message
        carries a global position (or its driver derives it from a local one in a stated
        frame).
    pos_frame : TangentFrame or None
        The frame of ``pos_ned``; None when the INS does not state where its local frame is.
    """

    t_gps_ns: int
    vel_ned: tuple[float, float, float]
    valid: Validity
    source: str
    device_time_ns: int
    pos_ned: tuple[float, float, float] | None = None
    vel_std_mps: tuple[float, float, float] | None = None
    lat_lon_alt: tuple[float, float, float] | None = None
    pos_frame: TangentFrame | None = None


@dataclass(frozen=True, slots=True)
class AttitudeSample:
    """Attitude of the INS body frame.

    Attributes
    ----------
    t_gps_ns : int
        Sample time, GPS ns.
    quat : tuple of 4 float
        Unit quaternion, scalar first, rotating body to NED (3-2-1 yaw, pitch, roll).
    valid : Validity
        Validity flags.
    source : str
        Message it came from.
    device_time_ns : int
        The same instant on the device clock, ns.
    """

    t_gps_ns: int
    quat: tuple[float, float, float, float]
    valid: Validity
    source: str
    device_time_ns: int


@dataclass(frozen=True, slots=True)
class EventSample:
    """A time-stamped external event (sync-in edge, e.g. a radar trigger).

    Attributes
    ----------
    t_gps_ns : int
        Event time, GPS ns.
    channel : str
        Input that saw it, e.g. ``"A"``.
    valid : Validity
        ``TIME`` when the event time is on a synchronised clock.
    source : str
        Message it came from.
    device_time_ns : int
        Event time on the device clock, ns.
    """

    t_gps_ns: int
    channel: str
    valid: Validity
    source: str
    device_time_ns: int


@dataclass(frozen=True, slots=True)
class TimeSample:
    """A device-clock → GPS time pair reported by the device (SBG UTC_TIME, SYSTEM_TIME...).

    Attributes
    ----------
    t_gps_ns : int
        GPS time, ns.
    device_time_ns : int
        The same instant on the device clock, ns.
    valid : Validity
        ``TIME`` when the device says its clock is valid.
    source : str
        Message it came from.
    """

    t_gps_ns: int
    device_time_ns: int
    valid: Validity
    source: str


Sample = VelocitySample | AttitudeSample | EventSample | TimeSample
"""Any navigation-side sample a driver yields."""


SampleFormat = Literal["complex64", "int16"]
"""How a radar source writes a pulse's samples, as the echo ring and the store hold them:
``complex64`` (float32 I/Q) or ``int16`` I/Q pairs (last axis I, Q)."""


def sample_shape(n_samples: int, sample_format: SampleFormat) -> tuple[int, ...]:
    """Shape of one pulse's samples in a given format: ``(S,)`` or ``(S, 2)`` for int16 I/Q."""
    return (n_samples,) if sample_format == "complex64" else (n_samples, 2)


def sample_dtype(sample_format: SampleFormat) -> np.dtype[np.generic]:
    """numpy dtype of the samples in a given format."""
    return np.dtype(np.complex64) if sample_format == "complex64" else np.dtype(np.int16)


def to_complex64(samples: npt.NDArray[np.generic]) -> npt.NDArray[np.complex64]:
    """Samples of either format as complex64 (int16 I/Q scaled by 1, i.e. in ADC counts).

    Parameters
    ----------
    samples : ndarray
        complex64 ``(..., S)`` (returned as is) or int16 ``(..., S, 2)``.
    """
    if samples.dtype == np.complex64:
        return samples  # type: ignore[return-value]
    # one conversion pass; the (I, Q) float32 pairs are the complex64 values
    pairs = np.ascontiguousarray(samples, dtype=np.float32)
    return pairs.view(np.complex64)[..., 0]


@dataclass(frozen=True, slots=True)
class EchoPacket:
    """Metadata of one radar pulse decoded into a caller's array row.

    Attributes
    ----------
    stream_id : int
        VITA 49 stream ID = receive channel.
    t_gps_ns : int
        Transmit time of the pulse, GPS ns.
    packet_count : int
        The 4-bit VITA 49 packet count (0..15).
    n_samples : int
        Complex samples written.
    valid_data : bool
        Trailer valid-data indicator (True when the trailer does not enable it).
    sample_loss : bool
        Trailer sample-loss indicator.
    over_range : bool
        Trailer over-range indicator.
    lost_before : int
        Packets missing between the previous packet of this stream and this one
        (from the 4-bit count, so modulo 16).
    context_mismatch : bool
        The stream's last context packet disagrees with the configured radar parameters
        (sample rate, bandwidth, RF frequency): the samples were taken under parameters
        the processing does not assume.
    """

    stream_id: int
    t_gps_ns: int
    packet_count: int
    n_samples: int
    valid_data: bool
    sample_loss: bool
    over_range: bool
    lost_before: int
    context_mismatch: bool = False


@dataclass(frozen=True)
class EchoPackets:
    """Metadata of radar pulses decoded into consecutive rows of a caller's array, as arrays.

    What the radar sources return: row ``i`` of the caller's array holds pulse ``i``. The
    fields are those of :class:`EchoPacket`, one array element per pulse, so that a batch
    of pulses is handed on with a few array operations and no object per pulse.

    Attributes
    ----------
    n_samples : int
        Complex samples written per pulse.
    stream_id : ndarray of int64, shape (P,)
        VITA 49 stream ID (32-bit, unsigned) = receive channel.
    t_gps_ns : ndarray of int64, shape (P,)
        Transmit time of each pulse, GPS ns.
    packet_count : ndarray of uint8, shape (P,)
        The 4-bit VITA 49 packet count (0..15).
    valid_data, sample_loss, over_range : ndarray of bool, shape (P,)
        Trailer indicators (``valid_data`` True when the trailer does not enable it).
    lost_before : ndarray of int64, shape (P,)
        Packets missing between the previous packet of the pulse's stream and it
        (modulo 16).
    context_mismatch : ndarray of bool, shape (P,)
        The stream's last context packet disagreed with the configured radar parameters.
    """

    n_samples: int
    stream_id: npt.NDArray[np.int64]
    t_gps_ns: npt.NDArray[np.int64]
    packet_count: npt.NDArray[np.uint8]
    valid_data: npt.NDArray[np.bool_]
    sample_loss: npt.NDArray[np.bool_]
    over_range: npt.NDArray[np.bool_]
    lost_before: npt.NDArray[np.int64]
    context_mismatch: npt.NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.t_gps_ns.shape[0])

    def __iter__(self) -> Iterator[EchoPacket]:
        """One :class:`EchoPacket` per pulse, in row order."""
        columns = [getattr(self, f.name).tolist() for f in fields(self)[1:]]
        for sid, t, count, valid, loss, over, lost, mismatch in zip(*columns, strict=True):
            yield EchoPacket(sid, t, count, self.n_samples, valid, loss, over, lost, mismatch)

    @classmethod
    def of(cls, packets: Sequence[EchoPacket], n_samples: int) -> EchoPackets:
        """The pulses of ``packets`` (one-packet decodes) as arrays."""
        return cls(
            n_samples,
            *(
                np.array([getattr(p, f.name) for p in packets], dtype=_DTYPES[f.name])
                for f in fields(cls)[1:]
            ),
        )

    @classmethod
    def concat(cls, parts: Sequence[EchoPackets], n_samples: int) -> EchoPackets:
        """The pulses of ``parts``, one after the other (none: no pulse)."""
        if not parts:
            return cls.of([], n_samples)
        if len(parts) == 1:
            return parts[0]
        return cls(
            n_samples,
            *(
                np.concatenate([getattr(p, f.name) for p in parts], dtype=_DTYPES[f.name])
                for f in fields(cls)[1:]
            ),
        )


_DTYPES: dict[str, npt.DTypeLike] = {
    "stream_id": np.int64,
    "t_gps_ns": np.int64,
    "packet_count": np.uint8,
    "valid_data": np.bool_,
    "sample_loss": np.bool_,
    "over_range": np.bool_,
    "lost_before": np.int64,
    "context_mismatch": np.bool_,
}
"""Element type of each array of :class:`EchoPackets`."""
