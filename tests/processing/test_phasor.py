"""Unit phasors of large phases in single precision (:mod:`sarmoco.processing.phasor`)."""

from __future__ import annotations

import numpy as np

from sarmoco.processing.phasor import phasor


def test_single_precision_phasor_matches_double_at_echo_phases() -> None:
    """Phases of 4 pi r / lambda at 15 GHz out to 5 km (about 3e6 rad): within 3e-7 of the
    double-precision phasor (a float32 phase there would be off by about 0.1 rad)."""
    phase = np.random.default_rng(1).uniform(-3.2e6, 3.2e6, (64, 257))
    exact = np.exp(1j * phase)
    got = phasor(phase)
    assert got.dtype == np.complex64 and got.shape == phase.shape
    assert np.max(np.abs(got - exact)) < 3e-7
    assert np.array_equal(phasor(phase, np.complex128), exact)


def test_phasor_of_a_scalar_and_of_small_phases() -> None:
    assert phasor(0.0) == 1.0
    assert abs(phasor(np.pi / 2) - 1j) < 1e-7
    small = np.linspace(-np.pi, np.pi, 101)
    assert np.max(np.abs(phasor(small) - np.exp(1j * small))) < 3e-7
