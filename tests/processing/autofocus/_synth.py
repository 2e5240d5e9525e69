"""Range-compressed point-target data formed directly from the exact range (docs/methods.md §1).

Each target contributes ``a sinc((r - R_k) / rho) exp(-j 4 pi R_k / lambda)`` to pulse k,
with ``R_k = |apc_k - target|`` in the imaging frame (x along track, y to the scene, z down).
Used to unit-test the estimators before and beside ``sarmoco.sim``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sarmoco.processing.autofocus.settings import AutofocusConfig
from sarmoco.processing.types import ComplexArray, FloatArray

WAVELENGTH_M = 0.02  # Ku, 15 GHz
SPEED_MPS = 17.5
DEPTH_M = 300.0
RES_M = 0.2  # range resolution c / 2B, m
BIN_M = 0.1  # range bin spacing, m
PRF_HZ = 250.0
SUBAPERTURE_S = 0.4
"""Autofocus subaperture the synthetic scenes (2 s and longer at PRF_HZ) are sized for, s:
their startup and release latency leave steady pulses with it (the key's default is
chosen on the independent acceptance flight)."""


def af_config(**settings: float) -> AutofocusConfig:
    """Autofocus settings for the synthetic scenes: :data:`SUBAPERTURE_S`, the rest as
    given or the defaults."""
    return AutofocusConfig(**({"subaperture_s": SUBAPERTURE_S} | settings))


@dataclass(frozen=True)
class Synthetic:
    """A synthetic range-compressed data set and its truth."""

    t_s: FloatArray
    range_m: FloatArray
    rc: ComplexArray
    d_yz_m: FloatArray  # (P, 2) APC deviation (y, z) from the reference track, m
    acc_yz_mps2: FloatArray  # (P, 2) its second derivative, m/s²
    targets: FloatArray  # (K, 3) imaging frame, m


def sine_motion(
    t_s: FloatArray, amp_yz: tuple[float, float], freq_hz: tuple[float, float]
) -> tuple[FloatArray, FloatArray]:
    """A smooth cross-track deviation and its exact second derivative."""
    d = np.zeros((t_s.size, 2))
    a = np.zeros((t_s.size, 2))
    for i, (amp, f) in enumerate(zip(amp_yz, freq_hz, strict=True)):
        w = 2.0 * np.pi * f
        d[:, i] = amp * np.sin(w * t_s + 0.7 * (i + 1))
        a[:, i] = -(w**2) * d[:, i]
    return d, a


def ground_target(x_m: float, slant_m: float) -> tuple[float, float, float]:
    """A target on flat ground at depth DEPTH_M, along-track x, broadside slant range."""
    return (x_m, float(np.sqrt(slant_m**2 - DEPTH_M**2)), DEPTH_M)


def make(
    duration_s: float,
    targets: list[tuple[float, float, float]],
    d_yz_m: FloatArray | None = None,
    acc_yz_mps2: FloatArray | None = None,
    range_span_m: tuple[float, float] = (880.0, 1120.0),
    speed_error_mps: float = 0.0,
    snr_db: float | None = None,
    seed: int = 0,
    along_m: FloatArray | None = None,
    beam: tuple[float, float] | None = None,
) -> Synthetic:
    """Form the data; the true track is ``x = (v + dv) t + along``, ``y, z = d_yz``.

    ``along_m`` (P,): along-track deviation of each pulse from ``(v + dv) t``, m; the
    returned times are then ``t + along / (v + dv)`` (the pulses' along-track position over
    the speed, as the along-track compensation gives them: uneven in slow time). ``beam``:
    (squint of the beam centre from the plane normal to the track, positive ahead; two-way
    half-width), rad: a target contributes only to the pulses that see it within the beam.
    """
    t = np.arange(round(duration_s * PRF_HZ)) / PRF_HZ - duration_s / 2.0
    rng_axis = np.arange(range_span_m[0], range_span_m[1], BIN_M)
    d = np.zeros((t.size, 2)) if d_yz_m is None else d_yz_m
    a = np.zeros((t.size, 2)) if acc_yz_mps2 is None else acc_yz_mps2
    speed = SPEED_MPS + speed_error_mps
    x = speed * t + (0.0 if along_m is None else along_m)
    apc = np.column_stack([x, d[:, 0], d[:, 1]])
    tg = np.asarray(targets, dtype=float)
    rc = np.zeros((t.size, rng_axis.size), dtype=np.complex128)
    for p in tg:
        r = np.linalg.norm(apc - p[None, :], axis=1)
        lit = np.ones(t.size)
        if beam is not None:
            squint = np.arcsin((p[0] - apc[:, 0]) / r)
            lit = (np.abs(squint - beam[0]) <= beam[1]).astype(float)
        rc += (
            lit[:, None]
            * np.sinc((rng_axis[None, :] - r[:, None]) / RES_M)
            * np.exp(-4j * np.pi * r / WAVELENGTH_M)[:, None]
        )
    if snr_db is not None:
        rng = np.random.default_rng(seed)
        sigma = 10 ** (-snr_db / 20.0) / np.sqrt(2.0)
        rc += sigma * (rng.standard_normal(rc.shape) + 1j * rng.standard_normal(rc.shape))
    return Synthetic(x / speed, rng_axis, rc.astype(np.complex64), d, a, tg)
