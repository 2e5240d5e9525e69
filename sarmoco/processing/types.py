"""Data types shared by every processing stage (and produced by sim, daemon).

Units are SI throughout (m, s, Hz, rad); times are GPS time in integer
nanoseconds (``int64``) unless a name says otherwise. Positions and velocities
are in local NED (north, east, down) unless a name says ``imaging`` (docs/methods.md §1).
Quaternions are scalar-first ``[w, x, y, z]`` and rotate body-frame vectors
into NED (3-2-1 yaw, pitch, roll).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from sarmoco.errors import ProcessingError
from sarmoco.keys import key

C_MPS = 299_792_458.0
"""Speed of light in vacuum, m/s."""

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complexfloating]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class RadarParams:
    """Waveform and receiver of one radar channel.

    Each field is also a configuration key (:func:`sarmoco.keys.key`, the daemon's
    ``[radar]`` section is this class plus the link's keys): its default, unit and bounds
    are in its metadata.

    Parameters
    ----------
    carrier_hz : float
        Centre (RF reference) frequency, Hz.
    bandwidth_hz : float
        Transmitted chirp bandwidth, Hz (> 0 for either chirp direction).
    pulse_width_s : float
        Chirp duration, s.
    sample_rate_hz : float
        Complex (I/Q) sample rate of the receiver, Hz.
    prf_hz : float
        Nominal pulse repetition frequency, Hz (actual pulse times may vary).
    n_samples : int
        Complex samples per pulse.
    range_gate_delay_s : float
        Two-way delay from the transmit time stamp to the first sample
        (``matched``) or to the dechirp reference (``dechirp``: the reference
        chirp is delayed by this much; a target at that delay has zero beat
        frequency), s.
    receive : {"matched", "dechirp"}
        ``matched``: baseband chirp echoes, compressed with a matched filter.
        ``dechirp``: FMCW / stretch processing, the receiver outputs beat
        signals, compressed with an FFT.
    chirp_direction : {"up", "down"}
        Sign of the transmitted chirp's frequency sweep: "up" (frequency rising,
        chirp rate +B/T_p) or "down" (falling, -B/T_p).
    iq_conjugate : bool
        The receiver delivers the complex conjugate of the baseband signal
        (spectral inversion: I/Q swapped or Q negated, e.g. a high-side local
        oscillator); the range compression conjugates the samples first.
    """

    carrier_hz: float = key(15.0e9, "RF reference (centre) frequency", unit="Hz", gt=0)
    bandwidth_hz: float = key(750.0e6, "Chirp bandwidth", unit="Hz", gt=0)
    pulse_width_s: float = key(10.0e-6, "Chirp duration", unit="s", gt=0)
    sample_rate_hz: float = key(1.0e9, "Complex I/Q sample rate", unit="Hz", gt=0)
    prf_hz: float = key(1000.0, "Nominal pulse repetition frequency", unit="Hz", gt=0)
    n_samples: int = key(4096, "Complex samples per pulse", gt=0)
    range_gate_delay_s: float = key(
        5.0e-6,
        "Two-way delay from the pulse time stamp to the first sample (matched) or to the "
        "dechirp reference (dechirp)",
        unit="s",
        ge=0,
    )
    receive: Literal["matched", "dechirp"] = key(
        "matched", "Receiver: pulsed LFM (matched filter) or dechirp-on-receive (FFT)"
    )
    chirp_direction: Literal["up", "down"] = key(
        "up", "Sweep of the transmitted chirp: up (frequency rising) or down (falling)"
    )
    iq_conjugate: bool = key(
        False,
        "The digitiser delivers the conjugate of the baseband I/Q (spectral inversion: I and Q "
        "swapped or Q negated, a high-side LO); the samples are conjugated before compression",
    )

    def __post_init__(self) -> None:
        for name in ("carrier_hz", "bandwidth_hz", "pulse_width_s", "sample_rate_hz", "prf_hz"):
            if not getattr(self, name) > 0:
                raise ProcessingError(f"RadarParams.{name}: {getattr(self, name)!r} is not > 0")
        if self.n_samples < 1:
            raise ProcessingError(f"RadarParams.n_samples: {self.n_samples!r} is not >= 1")
        if self.receive not in ("matched", "dechirp"):
            raise ProcessingError(
                f"RadarParams.receive: {self.receive!r} is not one of 'matched', 'dechirp'"
            )
        if self.chirp_direction not in ("up", "down"):
            raise ProcessingError(
                f"RadarParams.chirp_direction: {self.chirp_direction!r} is not one of 'up', 'down'"
            )
        if not isinstance(self.iq_conjugate, bool):
            raise ProcessingError(
                f"RadarParams.iq_conjugate: {self.iq_conjugate!r} is not true or false"
            )

    @property
    def wavelength_m(self) -> float:
        """Carrier wavelength, m."""
        return C_MPS / self.carrier_hz

    @property
    def chirp_rate_hz_per_s(self) -> float:
        """Magnitude of the chirp rate, K = B / T_p, Hz/s."""
        return self.bandwidth_hz / self.pulse_width_s

    @property
    def signed_chirp_rate_hz_per_s(self) -> float:
        """Chirp rate with the sweep's sign, K_s = +K (up) or -K (down), Hz/s."""
        k = self.chirp_rate_hz_per_s
        return k if self.chirp_direction == "up" else -k

    @property
    def range_resolution_m(self) -> float:
        """Slant-range resolution of an unweighted chirp, c / 2B, m (IRW is 0.886 of it)."""
        return C_MPS / (2.0 * self.bandwidth_hz)

    @property
    def near_range_m(self) -> float:
        """Slant range of the range-gate delay, m."""
        return C_MPS * self.range_gate_delay_s / 2.0


@dataclass(frozen=True)
class NavSamples:
    """INS (or GNSS) samples on the GPS time base.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (N,)
        Sample times, GPS ns, strictly increasing.
    vel_ned : ndarray of float64, shape (N, 3)
        Velocity of the IMU in NED, m/s.
    quat : ndarray of float64, shape (N, 4)
        Attitude, scalar-first quaternion rotating body to NED.
    pos_ned : ndarray of float64, shape (N, 3), optional
        Position of the IMU in the local NED frame, m (None when the source
        gives no position, e.g. an INS-only velocity stream).
    """

    t_ns: IntArray
    vel_ned: FloatArray
    quat: FloatArray
    pos_ned: FloatArray | None = None

    def __post_init__(self) -> None:
        n = self.t_ns.shape[0]
        if self.vel_ned.shape != (n, 3) or self.quat.shape != (n, 4):
            raise ProcessingError(
                f"NavSamples: shapes t{self.t_ns.shape} vel{self.vel_ned.shape} "
                f"quat{self.quat.shape} disagree (want (N,), (N,3), (N,4))"
            )
        if self.pos_ned is not None and self.pos_ned.shape != (n, 3):
            raise ProcessingError(f"NavSamples: pos_ned shape {self.pos_ned.shape} is not ({n}, 3)")


@dataclass(frozen=True)
class Image:
    """A focused complex image with its grid.

    Parameters
    ----------
    data : ndarray of complex, shape (n_az, n_rg)
        Complex pixels; axis 0 is azimuth (or the ground-grid x axis),
        axis 1 range (or ground-grid y).
    axis0_m, axis1_m : ndarray of float64
        Pixel-centre coordinates along each axis, m.
    frame : str
        What the axes are: ``"slant"`` (axis0 along-track x, axis1 slant range
        from the reference track), ``"ground"`` (x, y of the imaging frame at
        z = ground depth) or ``"polar"`` (spotlight: along/cross range about the
        scene centre).
    """

    data: ComplexArray
    axis0_m: FloatArray
    axis1_m: FloatArray
    frame: str

    @property
    def spacing_m(self) -> tuple[float, float]:
        """Pixel spacing along axis 0 and axis 1, m."""
        return (float(self.axis0_m[1] - self.axis0_m[0]), float(self.axis1_m[1] - self.axis1_m[0]))
