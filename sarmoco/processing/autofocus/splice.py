"""Splicing of per-subaperture estimates into continuous series, their double integration, and
the phase per range bin built from them (the envelope is moved by
:func:`sarmoco.processing.mocomp.shift_range`)."""

from __future__ import annotations

import math

import numba
import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import ComplexArray, FloatArray


def splice(
    t_centers_s: FloatArray,
    values: FloatArray,
    t_s: FloatArray,
    end_points: int = 3,
    end_degree: int = 1,
) -> FloatArray:
    """Piecewise-linear series through per-subaperture values, extended by a fit beyond the ends.

    Between the first and last centres the values are interpolated linearly. Before the first
    centre (and after the last) the series goes on from the end value along the
    least-squares polynomial of degree ``end_degree`` through the first (last) ``end_points``
    estimates, constrained to the end value: map drift measures the rate at a subaperture's
    centre, and the rates change fast enough that holding the end value over the last half
    subaperture leaves a large quadratic phase there.

    Parameters
    ----------
    t_centers_s : ndarray, shape (J,)
        Subaperture centre times, s, increasing.
    values : ndarray, shape (J, n)
        Estimates at the centres (any unit).
    t_s : ndarray, shape (P,)
        Output times, s.
    end_points : int
        Estimates in each end fit (1: hold the end value).
    end_degree : int
        Degree of the end fit (lowered to ``end_points - 1`` when fewer estimates exist).

    Returns
    -------
    ndarray, shape (P, n)
    """
    tc = np.asarray(t_centers_s, dtype=float)
    v = np.asarray(values, dtype=float).reshape(tc.size, -1)
    if v.shape[0] == 0:
        raise ProcessingError("splice: no subaperture estimates")
    t = np.asarray(t_s, dtype=float)
    out = np.column_stack([np.interp(t, tc, v[:, i]) for i in range(v.shape[1])])
    k = min(end_points, tc.size)
    degree = min(end_degree, k - 1)
    if degree < 1:
        return out
    powers = np.arange(1, degree + 1)
    for sel, end in ((slice(0, k), 0), (slice(tc.size - k, None), tc.size - 1)):
        outside = t < tc[0] if end == 0 else t > tc[-1]
        if np.any(outside):
            design = (tc[sel, None] - tc[end]) ** powers[None, :]
            coef = np.linalg.lstsq(design, v[sel] - v[end], rcond=None)[0]
            out[outside] = v[end] + ((t[outside, None] - tc[end]) ** powers[None, :]) @ coef
    return out


def integrate_twice(
    t_s: FloatArray, second_derivative: FloatArray, value0: FloatArray, slope0: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Integrate a series twice (trapezoid rule on the actual sample times) from given start.

    Parameters
    ----------
    t_s : ndarray, shape (P,)
        Sample times, s.
    second_derivative : ndarray, shape (P, n)
        E.g. accelerations in m/s² or rates in Hz/s.
    value0, slope0 : ndarray, shape (n,)
        Value and first derivative at ``t_s[0]``.

    Returns
    -------
    value, slope : ndarray, shape (P, n)
        The twice- and once-integrated series (m and m/s for m/s²; cycles and Hz for Hz/s).
    """
    f = np.asarray(second_derivative, dtype=float).reshape(len(t_s), -1)
    dt = np.diff(t_s)[:, None]
    zero = np.zeros((1, f.shape[1]))
    slope = slope0 + np.vstack([zero, np.cumsum(0.5 * dt * (f[1:] + f[:-1]), axis=0)])
    value = value0 + np.vstack([zero, np.cumsum(0.5 * dt * (slope[1:] + slope[:-1]), axis=0)])
    return value, slope


def zero_line_start(
    t_s: FloatArray, second_derivative: FloatArray, window: slice
) -> tuple[FloatArray, FloatArray]:
    """Start value and slope that pin the unobservable constant and linear terms.

    The double integral of ``second_derivative`` started with the returned value and slope
    at ``t_s[0]`` has zero mean and zero trend (least squares) over the samples ``window``
    (at least two). Shapes and units as :func:`integrate_twice`; returns ``value0, slope0``
    of shape (n,).
    """
    f = np.asarray(second_derivative, dtype=float).reshape(len(t_s), -1)
    zero = np.zeros(f.shape[1])
    value = integrate_twice(t_s, f, zero, zero)[0]
    idx = np.arange(len(t_s))[window]
    if idx.size < 2:
        idx = np.arange(min(2, len(t_s)))
    design = np.column_stack([np.ones(idx.size), np.asarray(t_s[idx], dtype=float) - t_s[0]])
    coef = np.linalg.lstsq(design, value[idx], rcond=None)[0]
    return -coef[0], -coef[1]


def line_fit(t_s: FloatArray, y: FloatArray) -> FloatArray:
    """Least-squares line ``a + b t`` through each column of ``y`` (P, n), evaluated at t."""
    design = np.column_stack([np.ones_like(t_s), t_s - t_s.mean()])
    coef = np.linalg.lstsq(design, y, rcond=None)[0]
    return np.asarray(design @ coef, dtype=float)


_ANCHOR = 64
"""The recurrence of :func:`_rotate` restarts from exact sines and cosines every so many
samples (its rounding error stays near 1e-14)."""


@numba.njit(cache=True, nogil=True)
def _cis(cycles: float) -> complex:
    ph = -2.0 * math.pi * (cycles - math.floor(cycles))
    return complex(math.cos(ph), math.sin(ph))


@numba.njit(cache=True, nogil=True)
def _rotate(
    data: ComplexArray,
    poly: FloatArray,
    x0: float,
    dx: float,
    k0: int,
    k1: int,
    out: ComplexArray,
) -> None:
    """``out[p, k] = data[p, k] exp(-2πi c)`` for columns ``k0 <= k < k1``, with
    ``c = poly[p, 0] + poly[p, 1] x + poly[p, 2] x²`` cycles at ``x = x0 + (k - k0) dx``.

    Along k the factor follows a second-order recurrence (constant second difference of
    the quadratic), restarted every ``_ANCHOR`` samples.
    """
    second = np.empty(data.shape[0], dtype=np.complex128)
    for p in range(data.shape[0]):
        second[p] = _cis(2.0 * poly[p, 2] * dx * dx)
    for p in range(data.shape[0]):
        c0, c1, c2 = poly[p, 0], poly[p, 1], poly[p, 2]
        z = 0j
        step = 0j
        for k in range(k0, k1):
            i = k - k0
            if i % _ANCHOR == 0:
                x = x0 + i * dx
                z = _cis(c0 + x * (c1 + c2 * x))
                step = _cis(c1 * dx + c2 * dx * (2.0 * x + dx))
            out[p, k] = data[p, k] * z
            z *= step
            step *= second[p]


def remove_phase(
    rc: ComplexArray, cycles_per_order: FloatArray, delta_range_m: FloatArray
) -> ComplexArray:
    """Remove the phase error :func:`phase_screen` describes: ``rc exp(-j phase)``.

    Parameters
    ----------
    rc : ndarray, shape (P, S)
        Range-compressed pulses on a uniform range axis.
    cycles_per_order : ndarray, shape (P, 3)
        Double integrals of κ0, κ1, κ2 (cycles, cycles/m, cycles/m²).
    delta_range_m : ndarray, shape (S,)
        ``R - R_c`` of each range bin, m.

    Returns
    -------
    ndarray, shape (P, S), the dtype of ``rc``
    """
    out = np.empty_like(rc)
    dr = np.asarray(delta_range_m, dtype=float)
    if rc.size:
        poly = np.ascontiguousarray(cycles_per_order, dtype=float)
        dx = float(dr[1] - dr[0]) if dr.size > 1 else 0.0
        if dr.size > 1 and not np.allclose(np.diff(dr), dx, rtol=1e-9, atol=0.0):
            raise ProcessingError("remove_phase: the range axis is not uniform")
        _rotate(rc, poly, float(dr[0]), dx, 0, dr.size, out)
    return out


def phase_screen(cycles_per_order: FloatArray, delta_range_m: FloatArray) -> FloatArray:
    """Phase error per pulse and range bin, rad: ``2π (Φ0 + Φ1 Δd + Φ2 Δd²)``.

    Parameters
    ----------
    cycles_per_order : ndarray, shape (P, 3)
        Double integrals of κ0, κ1, κ2 (cycles, cycles/m, cycles/m²).
    delta_range_m : ndarray, shape (S,)
        ``R - R_c`` of each range bin, m.
    """
    powers = np.vstack([np.ones_like(delta_range_m), delta_range_m, delta_range_m**2])
    return np.asarray(2.0 * np.pi * (cycles_per_order @ powers), dtype=float)


def warm_up() -> None:
    """Compile the kernel of :func:`remove_phase` (or load it from numba's cache) on
    complex64 pulses, the range-compressed data's dtype.

    numba compiles at a kernel's first call: seconds on an idle board, tens of seconds
    under load. The daemon calls this before it reads its links (``sarmoco run``).
    """
    remove_phase(np.ones((2, 4), np.complex64), np.zeros((2, 3)), 0.1 * np.arange(4.0))
