"""Autofocus corrections of a run of pulses: LOS shift of the envelope and phase per bin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sarmoco.processing.autofocus.splice import phase_screen, remove_phase
from sarmoco.processing.mocomp import shift_range
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray


@dataclass(frozen=True)
class Corrections:
    """Autofocus corrections of a run of pulses.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    los_m : ndarray, shape (P,)
        Estimated LOS displacement at the scene-centre look angle (toward the scene), m;
        the envelope is shifted by this much (a peak at R - d_los goes back to R).
    phase_cycles : ndarray, shape (P, 3)
        Double integrals of κ0, κ1, κ2 (cycles, cycles/m, cycles/m²).
    ref_range_m : float
        R_c of the κ model, m.
    """

    t_ns: IntArray
    los_m: FloatArray
    phase_cycles: FloatArray
    ref_range_m: float

    def phase_rad(self, range_m: FloatArray) -> FloatArray:
        """Phase error of every pulse and range bin, rad, shape (P, S)."""
        return phase_screen(self.phase_cycles, np.asarray(range_m) - self.ref_range_m)

    def apply(self, rc: ComplexArray, range_m: FloatArray) -> ComplexArray:
        """Shift the envelopes and remove the phase error: returns corrected (P, S) data."""
        shifted = shift_range(rc, self.los_m / float(range_m[1] - range_m[0]))
        return remove_phase(shifted, self.phase_cycles, np.asarray(range_m) - self.ref_range_m)
