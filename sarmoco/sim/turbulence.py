"""Seeded turbulence: coloured random processes as sums of sinusoids.

Cross-track (east) and vertical (down) displacement, along-track speed variation and
roll/pitch/yaw each follow an independent seeded Gaussian-like process with the one-sided
power spectral density of a second-order low-pass (Dryden-like),
``S(f) = S0 / (1 + (f / f_c)**2)**2`` for ``f_c / BAND_RATIO <= f <= BAND_RATIO f_c``. Each
process is a sum of :data:`N_COMPONENTS` sinusoids, so position, velocity and acceleration
are exact analytic derivatives of one smooth function (:mod:`sarmoco.sim.trajectory`).

Frames: NED deviations about a track heading north; m, m/s, m/s^2, rad, Hz, s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sarmoco.processing.types import FloatArray
from sarmoco.sim.motionspec import MotionSpec

N_COMPONENTS = 256
"""Sinusoids per turbulence channel."""

BAND_RATIO = 10.0
"""The turbulence spectrum spans f_c / BAND_RATIO .. f_c * BAND_RATIO."""

TIME_BLOCK = 4096
"""Times per block of :meth:`SinusoidSum.derivatives` (cache and memory)."""


def lowpass2_psd(f_hz: FloatArray, corner_hz: float) -> FloatArray:
    """Unnormalised second-order low-pass PSD shape ``1 / (1 + (f/f_c)**2)**2``."""
    return np.asarray(1.0 / (1.0 + (np.asarray(f_hz) / corner_hz) ** 2) ** 2, dtype=np.float64)


@dataclass(frozen=True)
class SinusoidSum:
    """``x(t) = sum_m a_m cos(2 pi f_m t + phi_m)`` and its derivatives.

    Parameters
    ----------
    freq_hz, amp, phase_rad : ndarray, shape (M,)
    """

    freq_hz: FloatArray
    amp: FloatArray
    phase_rad: FloatArray

    @classmethod
    def coloured(cls, rms: float, corner_hz: float, rng: np.random.Generator) -> SinusoidSum:
        """A realisation of the documented low-pass spectrum with total rms ``rms``."""
        edges = np.geomspace(corner_hz / BAND_RATIO, corner_hz * BAND_RATIO, N_COMPONENTS + 1)
        freq = edges[:-1] + rng.random(N_COMPONENTS) * np.diff(edges)
        power = lowpass2_psd(freq, corner_hz) * np.diff(edges)
        amp = np.sqrt(2.0 * power / power.sum()) * rms
        return cls(freq, amp, rng.uniform(0.0, 2.0 * np.pi, N_COMPONENTS))

    def derivatives(self, t_s: FloatArray, order: int = 2) -> list[FloatArray]:
        """[x, x', ..., x^(order)] at ``t_s``, each shape (P,).

        Evaluated :data:`TIME_BLOCK` times at a time: the (times x components) phase
        matrix stays in cache and memory is bounded for any length of ``t_s`` (a 30-minute
        run's 315 000 pulses would otherwise make 645 MB matrices).
        """
        w = 2.0 * np.pi * self.freq_hz
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        weights = [self.amp * w**k for k in range(order + 1)]
        out = [np.empty(t.size) for _ in weights]
        for i in range(0, t.size, TIME_BLOCK):
            arg = np.outer(t[i : i + TIME_BLOCK], w) + self.phase_rad
            c, s = np.cos(arg), np.sin(arg)
            basis = (c, -s, -c, s)
            for k, wk in enumerate(weights):
                out[k][i : i + TIME_BLOCK] = basis[k % 4] @ wk
        return out


@dataclass(frozen=True)
class TurbulenceDeviation:
    """Seeded turbulence (see the module docstring)."""

    spec: MotionSpec

    def _channels(self) -> list[SinusoidSum]:
        rng = np.random.default_rng(self.spec.seed)
        s = self.spec
        rms = (s.along_speed_rms_mps, s.cross_track_rms_m, s.vertical_rms_m) + (
            s.attitude_rms_rad,
        ) * 3
        return [SinusoidSum.coloured(r, s.corner_hz, rng) for r in rms]

    def __call__(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        along, east, down, *att = self._channels()
        t = np.asarray(t_s, dtype=np.float64)
        pos, vel, acc = (np.zeros((t.size, 3)) for _ in range(3))
        # along track: the process is the speed; position is its integral (a sine sum too)
        v, a = along.derivatives(t, 1)
        integ = SinusoidSum(
            along.freq_hz, along.amp / (2 * np.pi * along.freq_hz), along.phase_rad - np.pi / 2
        )
        pos[:, 0], vel[:, 0], acc[:, 0] = integ.derivatives(t, 0)[0], v, a
        for axis, ch in ((1, east), (2, down)):
            pos[:, axis], vel[:, axis], acc[:, axis] = ch.derivatives(t, 2)
        euler = np.stack([ch.derivatives(t, 0)[0] for ch in att], axis=1)
        return pos, vel, acc, euler
