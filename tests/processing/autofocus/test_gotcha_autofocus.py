"""The autofocus on GOTCHA (spotlight, 2 deg, 234 pulses).

4a: the per-pulse ML phase estimator of ``sarmoco.processing.autofocus.spotlight`` (PGA's
estimator at the brightest pixels) must sharpen the data as provided (lower entropy).
4b: a known LOS error (2.5 range cells smooth + 3 rad rms random walk) injected into the real
phase history is recovered by range alignment + phase passes (``bench/gotcha_autofocus.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sarmoco.drivers.gotcha import read_gotcha
from sarmoco.processing.autofocus.spotlight import spotlight_autofocus
from sarmoco.processing.imaging import (
    PlaneGrid,
    backproject,
    compressed_from_phase_history,
    facing_heading,
)
from sarmoco.processing.metrics import image_entropy
from sarmoco.processing.types import C_MPS, ComplexArray, Image
from tests.workloads.gotcha_autofocus import recover


def test_autofocus_sharpens_provided_data(gotcha_files: list[Path]) -> None:
    d = read_gotcha(gotcha_files)
    grid = PlaneGrid.centred(
        (0.0, 0.0, 0.0), 240, 240, 0.25, 0.25, facing_heading(d.apc_m, (0.0, 0.0, 0.0))
    )

    def image(ph: ComplexArray) -> Image:
        rc, r_axis, fc = compressed_from_phase_history(ph, d.freq_hz)
        return backproject(rc, r_axis, d.apc_m, C_MPS / fc, grid, ref_range_m=d.r0_m)

    before = image(d.phase_history)
    res = spotlight_autofocus(
        d.phase_history,
        d.freq_hz,
        d.apc_m,
        d.r0_m,
        grid.positions().reshape(-1, 3),
        before.data.ravel(),
    )
    h0 = image_entropy(before.data)
    h1 = image_entropy(image(res.apply(d.phase_history, d.freq_hz)).data)
    print(f"\nentropy as provided {h0:.3f}, after our spotlight autofocus {h1:.3f}")
    # measured: 7.104 as provided, 7.008 after (0.19 rad rms phase removed): the bar is half
    # that drop, so a no-op (or an estimate of the wrong sign) fails
    assert h1 < h0 - 0.05, (h0, h1)
    assert res.rms_updates_rad[-1] < 0.01
    assert np.all(res.los_m == 0.0)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def test_autofocus_recovers_injected_error(gotcha_files: list[Path]) -> None:
    r = recover(read_gotcha(gotcha_files))
    assert np.ptp(r.injected_m) / r.cell_m > 2.0  # the envelope error spans 2-3 range cells
    assert r.entropy_corrupted > 1.3 * r.entropy_provided
    # measured: 7.104 provided, 10.078 corrupted, 7.054 recovered (the bar is +1 %)
    assert r.entropy_recovered <= 1.01 * r.entropy_provided, r
    # measured: envelope 18.4 mm rms = 0.076 cell; carrier phase 0.192 rad rms, i.e. the
    # data's own phase error that acceptance 4a removes (0.19 rad rms)
    assert _rms(r.envelope_error_m) < 0.1 * r.cell_m
    assert _rms(r.phase_error_rad) < 0.25
    assert r.result.rms_updates_rad[-1] < 0.03
