"""Point-target and scene metrics against closed-form responses."""

from __future__ import annotations

import numpy as np
import pytest

from sarmoco.errors import ProcessingError
from sarmoco.processing.metrics import (
    cut_metrics,
    image_contrast,
    image_entropy,
    point_target_metrics,
    upsample_cut,
)
from sarmoco.processing.types import ComplexArray, FloatArray, Image


def _band_cut(
    n: int, band_frac: float, weights: FloatArray | None, shift: float, carrier: float
) -> ComplexArray:
    """A band-limited impulse at ``shift`` samples from the centre, with a spectral carrier."""
    nb = round(n * band_frac)
    spec = np.zeros(n, dtype=np.complex128)
    k = np.arange(nb) - nb // 2
    w = np.ones(nb) if weights is None else weights
    spec[k % n] = w * np.exp(-2j * np.pi * k * (n // 2 + shift) / n)
    return np.asarray(np.fft.ifft(spec) * np.exp(2j * np.pi * carrier * np.arange(n)))


@pytest.mark.parametrize("shift", [0.0, 0.3, 0.5])
def test_unweighted_sinc_limits(shift: float) -> None:
    cut = _band_cut(512, 0.5, None, shift, carrier=0.31)
    m = cut_metrics(cut, spacing_m=0.1, origin_m=-25.6)
    res = 0.1 / 0.5  # resolution cell = 1 / band
    assert m.pslr_db == pytest.approx(-13.26, abs=0.03)
    assert m.irw_m == pytest.approx(0.886 * res, rel=0.003)
    assert m.islr_db == pytest.approx(-9.9, abs=0.15)
    assert m.mainlobe_m == pytest.approx(2 * res, rel=0.03)
    assert m.peak_m == pytest.approx(-25.6 + (256 + shift) * 0.1, abs=1e-3)


def test_hamming_weighted_cut() -> None:
    nb = 200
    ham = 0.54 - 0.46 * np.cos(2 * np.pi * np.arange(nb) / (nb - 1))
    m = cut_metrics(_band_cut(1024, nb / 1024, ham, 0.0, 0.0), spacing_m=1.0)
    assert m.pslr_db == pytest.approx(-42.7, abs=0.6)
    assert m.irw_m == pytest.approx(1.30 * 1024 / nb, rel=0.02)


def test_upsample_keeps_samples() -> None:
    x = _band_cut(64, 0.6, None, 0.2, carrier=0.4)
    up = upsample_cut(x, 8)
    assert np.allclose(np.abs(up[::8]), np.abs(x), atol=1e-12)


def test_point_target_2d_with_position_error() -> None:
    n0, n1 = 128, 96
    c0 = _band_cut(n0, 0.4, None, 0.25, carrier=-0.2)
    c1 = _band_cut(n1, 0.5, None, -0.4, carrier=0.35)
    ax0 = np.arange(n0, dtype=np.float64) * 0.2 - 10.0
    ax1 = np.arange(n1, dtype=np.float64) * 0.1 + 500.0
    img = Image(np.outer(c0, c1).astype(np.complex64), ax0, ax1, "ground")
    true = (ax0[n0 // 2] + 0.25 * 0.2, ax1[n1 // 2] - 0.4 * 0.1)
    m = point_target_metrics(img, expected_m=(true[0] + 0.01, true[1]), search_radius_m=2.0)
    assert m.axis0.irw_m == pytest.approx(0.886 * 0.2 / 0.4, rel=0.005)
    assert m.axis1.irw_m == pytest.approx(0.886 * 0.1 / 0.5, rel=0.005)
    assert m.axis0.pslr_db == pytest.approx(-13.26, abs=0.05)
    assert m.position_error_m is not None
    assert m.position_error_m[0] == pytest.approx(-0.01, abs=1e-3)
    assert m.position_error_m[1] == pytest.approx(0.0, abs=1e-3)


def test_entropy_and_contrast() -> None:
    flat = np.ones((16, 16), dtype=np.complex64)
    assert image_entropy(flat) == pytest.approx(np.log(256))
    assert image_contrast(flat) == pytest.approx(0.0)
    spike = np.zeros((16, 16), dtype=np.complex64)
    spike[3, 4] = 2.0
    assert image_entropy(spike) == pytest.approx(0.0)
    assert image_contrast(spike) == pytest.approx(np.sqrt(255))


def test_bad_inputs_raise() -> None:
    with pytest.raises(ProcessingError):
        cut_metrics(np.ones(3, dtype=np.complex128), 1.0)
    with pytest.raises(ProcessingError):
        image_entropy(np.zeros((4, 4)))


def test_peak_index_picks_the_lobe_of_the_chosen_target() -> None:
    weak = _band_cut(512, 0.5, None, 0.0, carrier=0.0)
    strong = 3.0 * np.roll(weak, 60)  # a brighter target 60 samples further on the same cut
    cut = weak + strong
    m = cut_metrics(cut, spacing_m=1.0, peak_index=256)
    # the bright neighbour's sidelobes pull the weak peak by ~0.06 sample
    assert m.peak_m == pytest.approx(256.0, abs=0.1)
    assert m.irw_m == pytest.approx(0.886 * 2.0, rel=0.01)
    assert cut_metrics(cut, spacing_m=1.0).peak_m == pytest.approx(316.0, abs=0.05)


@pytest.mark.parametrize("squint_deg", [8.0, -12.0])
def test_cuts_through_the_peak_of_a_turned_response(squint_deg: float) -> None:
    """An unweighted sinc turned by a squint (a crabbed flight's response on the ground
    grid), its peak half a pixel off the grid across track: cuts through the brightest
    pixel see unequal sidelobes (> 1 dB apart, one side above -13 dB); cuts through the
    peak found in two dimensions read the sinc's -13.26 dB and 0.886 x resolution."""
    res, step = 0.2, 0.1
    a = np.radians(squint_deg)
    axis = np.arange(-80, 81) * step
    x, y = np.meshgrid(axis, axis + 0.5 * step, indexing="ij")
    u, v = x * np.cos(a) + y * np.sin(a), -x * np.sin(a) + y * np.cos(a)
    carrier = np.exp(2j * np.pi * (0.21 * x / step + 0.13 * y / step))
    img = Image(np.sinc(u / res) * np.sinc(v / res) * carrier, axis, axis, "ground")
    assert point_target_metrics(img).axis0.pslr_db > -13.0
    peak = point_target_metrics(img, through_peak=True)
    # the cuts of the same response through its true peak (x, 0) and (0, y)
    true0 = cut_metrics(np.sinc(axis * np.cos(a) / res) * np.sinc(-axis * np.sin(a) / res), step)
    true1 = cut_metrics(np.sinc(axis * np.sin(a) / res) * np.sinc(axis * np.cos(a) / res), step)
    for m, ref in ((peak.axis0, true0), (peak.axis1, true1)):
        assert m.pslr_db == pytest.approx(ref.pslr_db, abs=0.1)
        assert m.irw_m == pytest.approx(ref.irw_m, rel=0.01)
