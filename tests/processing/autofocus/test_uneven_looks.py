"""Map drift on pulses unevenly spaced in time (along-track placement of an accelerating
platform)."""

from __future__ import annotations

import numpy as np

from sarmoco.processing.autofocus import doppler_rate as dr
from tests.processing.autofocus import _synth as S

RANGE_M = 1000.0
"""Broadside slant range of every target, m."""


def _line(t_s: np.ndarray, x_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Range-compressed echoes of one target at along-track ``x_m`` seen from APC
    ``(SPEED t, 0, 0)`` at times ``t_s`` (s); returns (data (P, S), range axis)."""
    target = np.array(S.ground_target(x_m, RANGE_M))
    apc = np.column_stack([S.SPEED_MPS * t_s, np.zeros((t_s.size, 2))])
    r = np.linalg.norm(apc - target[None, :], axis=1)
    axis = np.arange(RANGE_M - 3.0, RANGE_M + 3.0, S.BIN_M)
    phase = -4.0 * np.pi * r / S.WAVELENGTH_M
    rc = np.sinc((axis[None, :] - r[:, None]) / S.RES_M) * np.exp(1j * phase)[:, None]
    return rc.astype(np.complex64), axis


def _rate(rc: np.ndarray, axis: np.ndarray, t_s: np.ndarray) -> float:
    bins = dr.select_lines(rc, 1, 4)
    ref = dr.nominal_rate(axis[bins], S.SPEED_MPS, S.WAVELENGTH_M)
    return float(dr.map_drift(dr.gather_bands(rc, bins, 1), t_s, ref)[0][0])


def test_unevenly_spaced_pulses_give_no_rate_error() -> None:
    """Along-track placement gives each pulse the time the reference track passes its APC:
    an accelerating platform's pulses come ever further apart, and the echo is the nominal
    chirp in those times. Map drift must read zero. Taking the looks' samples as evenly
    spaced put a target's Doppler f at f (1 + a dt/v) in the later look: a rate error
    proportional to f (-1.16 / +1.26 Hz/s for targets 40 m behind and ahead of the
    subaperture centre, 0.5 m/s² along track)."""
    accel = 0.5  # m/s² along track
    n = round(0.4 * S.PRF_HZ)
    u = np.arange(n) / S.PRF_HZ - 0.2  # pulse times, s
    tau = u + 0.5 * accel / S.SPEED_MPS * (u + 10.0) ** 2  # x / v0 of the speeding platform
    tau -= tau.mean()
    for x_m in (-40.0, 40.0):
        rc, axis = _line(tau, x_m)
        rate = _rate(rc, axis, tau)
        # measured +0.12 / -0.015 Hz/s (each look's spectrum on the common frequency axis)
        assert abs(rate) < 0.2, (x_m, rate)
