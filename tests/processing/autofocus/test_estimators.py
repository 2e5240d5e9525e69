"""Doppler-rate estimators, separation, splicing and PGA on synthetic range-compressed targets."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sarmoco.processing.autofocus import AutofocusGeometry
from sarmoco.processing.autofocus import doppler_rate as dr
from sarmoco.processing.autofocus.lines import (
    fit_accel,
    los_accel,
    measure_line_rates,
    select_bands,
)
from sarmoco.processing.autofocus.pga import pga
from sarmoco.processing.autofocus.report import LineRates
from sarmoco.processing.autofocus.separation import fit_accelerations, fit_range_polynomial
from sarmoco.processing.autofocus.splice import integrate_twice, zero_line_start
from tests.processing.autofocus import _synth as S

ACC_YZ = (0.5, -0.8)


@pytest.fixture(scope="module")
def accelerated() -> S.Synthetic:
    """0.6 s at constant cross-track acceleration (a_y, a_z), five targets across range."""
    t = np.arange(round(0.6 * S.PRF_HZ)) / S.PRF_HZ - 0.3
    acc = np.tile(ACC_YZ, (t.size, 1))
    d = 0.5 * acc * t[:, None] ** 2
    tg = [S.ground_target(x, r) for x, r in [(0, 900), (3, 950), (-2, 1000), (1, 1050), (4, 1100)]]
    return S.make(0.6, tg, d, acc, snr_db=10.0)


@pytest.mark.parametrize("method", ["map_drift", "contrast"])
def test_rate_sign_and_size(accelerated: S.Synthetic, method: str) -> None:
    """The measured rate error is +(2/λ)(a_y sin β + a_z cos β) in the docs/methods.md §1 frame."""
    syn = accelerated
    bins = dr.select_lines(syn.rc, 5, 10)
    assert bins.size == 5
    bands = dr.gather_bands(syn.rc, bins, 1)
    ref = dr.nominal_rate(syn.range_m[bins], S.SPEED_MPS, S.WAVELENGTH_M)
    if method == "map_drift":
        delta, quality = dr.map_drift(bands, syn.t_s, ref)
    else:
        delta, quality = dr.contrast_optimisation(bands, syn.t_s, ref, 150.0)
    beta = np.arccos(S.DEPTH_M / syn.range_m[bins])
    expect = 2.0 / S.WAVELENGTH_M * (ACC_YZ[0] * np.sin(beta) + ACC_YZ[1] * np.cos(beta))
    np.testing.assert_allclose(delta, expect, atol=0.5)
    assert np.all(quality > 0.3)


@pytest.mark.parametrize("method", ["map_drift", "contrast"])
def test_rates_do_not_depend_on_the_data_scale(accelerated: S.Synthetic, method: str) -> None:
    """Full-scale radar data (int16 echoes range-compressed over thousands of samples reach
    1e8 per bin) give the same rates and qualities as unit-scale data, in single precision
    (a product of two sums of squares overflowed float32 there: quality 0, no correction)."""
    syn = accelerated
    bins = dr.select_lines(syn.rc, 5, 10)
    ref = dr.nominal_rate(syn.range_m[bins], S.SPEED_MPS, S.WAVELENGTH_M)
    results = []
    for scale in (1.0, 1e8):
        bands = (dr.gather_bands(syn.rc, bins, 1) * scale).astype(np.complex64)
        if method == "map_drift":
            results.append(dr.map_drift(bands, syn.t_s, ref))
        else:
            results.append(dr.contrast_optimisation(bands, syn.t_s, ref, 150.0))
    (d1, q1), (d2, q2) = results
    np.testing.assert_allclose(d2, d1, atol=1e-3)
    np.testing.assert_allclose(q2, q1, atol=1e-4)
    assert np.all(q2 > 0.3)


def test_separation_recovers_accelerations(accelerated: S.Synthetic) -> None:
    syn = accelerated
    bins = dr.select_lines(syn.rc, 5, 10)
    bands = dr.gather_bands(syn.rc, bins, 1)
    ref = dr.nominal_rate(syn.range_m[bins], S.SPEED_MPS, S.WAVELENGTH_M)
    delta, _ = dr.map_drift(bands, syn.t_s, ref)
    (ay, az), res = fit_accelerations(
        syn.range_m[bins], delta, np.ones(bins.size), S.DEPTH_M, S.WAVELENGTH_M
    )
    assert abs(ay - ACC_YZ[0]) < 0.02 and abs(az - ACC_YZ[1]) < 0.1
    assert res < 0.5


def test_few_lines_give_a_line_of_sight_acceleration() -> None:
    """Two or three lines a few metres apart in range cannot separate a_y from a_z: their
    rates, 0.3 Hz/s apart as noise leaves them, give the line-of-sight acceleration that a
    common rate error means, not tens of m/s² (the exact 2 x 2 solve)."""
    geo = AutofocusGeometry(0.02, 17.5, 438.0, 900.0)
    for r, rates in [([846.0, 851.0], [2.0, 2.3]), ([846.0, 849.0, 851.0], [2.0, 2.2, 2.3])]:
        n = len(r)
        lines = LineRates(np.array(r), np.array(rates), np.ones(n), np.ones(n), np.full(n, 30.0))
        (ay, az), _ = fit_accel(lines, geo)
        a_los = float(los_accel(np.array([ay, az]), geo))
        # rate = (2/λ) a_los cos(β - β_c): within 0.1 % of (2/λ) a_los at these ranges
        assert a_los == pytest.approx(np.mean(rates) * geo.wavelength_m / 2.0, rel=0.05)
        assert np.hypot(ay, az) == pytest.approx(abs(a_los), rel=1e-9)


def test_range_polynomial_and_outlier() -> None:
    r = np.linspace(900.0, 1100.0, 12)
    k = np.array([3.0, 0.02, -1e-4])
    rates = k[0] + k[1] * (r - 1000) + k[2] * (r - 1000) ** 2
    rates[4] += 40.0  # one bad line
    est, _ = fit_range_polynomial(r, rates, np.ones(r.size), 1000.0, 2)
    np.testing.assert_allclose(est, k, rtol=1e-6, atol=1e-9)
    lin, _ = fit_range_polynomial(r, rates, np.ones(r.size), 1000.0, 1)
    assert lin[2] == 0.0


def test_double_integration_pins_line() -> None:
    t = np.linspace(0.0, 3.0, 1201)
    acc = np.cos(2.0 * t)[:, None]
    true = -np.cos(2.0 * t) / 4.0
    window = slice(200, 800)
    got = integrate_twice(t, acc, *zero_line_start(t, acc, window))[0][:, 0]
    fit = np.polyval(np.polyfit(t[window], true[window], 1), t)
    np.testing.assert_allclose(got, true - fit, atol=1e-5)
    zero = np.zeros(1)
    start = integrate_twice(t, acc, zero, zero)[0][:, 0]
    np.testing.assert_allclose(start, (1.0 - np.cos(2.0 * t)) / 4.0, atol=1e-5)


def test_pga_recovers_smooth_and_random_phase() -> None:
    rng = np.random.default_rng(0)
    n_p = 512
    k = np.arange(n_p)
    phi = 3.0 * np.sin(2 * np.pi * 1.5 * k / n_p) + np.cumsum(rng.normal(0.0, 0.01, n_p))
    lines = []
    for _ in range(20):
        hist = (rng.random() + 0.5) * np.exp(2j * np.pi * rng.integers(n_p) * k / n_p + 1j * phi)
        noise = 0.05 * (rng.standard_normal(n_p) + 1j * rng.standard_normal(n_p))
        lines.append(np.fft.fft(hist + noise))
    est, updates = pga(np.array(lines))
    true = phi - np.polyval(np.polyfit(k, phi, 1), k)
    assert np.std(est - true) < 0.05
    assert updates[-1] < 0.02


def test_a_line_lit_for_part_of_the_subaperture_weighs_little() -> None:
    """Two targets over a 0.4 s subaperture without motion, at 10 dB per pulse: one lit
    throughout, one entering the beam 0.12 s in. Map drift gives the late one a rate 12 Hz/s
    off (its first look holds a third of its echo), at quality 0.82 and, by its peak alone,
    0.43 of the other line's weight (measured). Its illumination balance is under 0.05 and
    the other's over 0.8, and its weight in the fits at most a percent of the other's."""
    whole = S.make(0.4, [S.ground_target(0.0, 950.0)], snr_db=10.0)
    late = S.make(0.4, [S.ground_target(1.0, 1050.0)]).rc
    late[: int(0.3 * late.shape[0])] = 0.0
    bands = select_bands(whole.rc + late, whole.range_m, S.af_config())
    assert bands.bins.size == 2
    near_first = np.argsort(whole.range_m[bands.bins])
    balance = bands.balance[near_first]
    assert balance[0] > 0.8 and balance[1] < 0.05, balance
    geo = AutofocusGeometry(S.WAVELENGTH_M, S.SPEED_MPS, S.DEPTH_M, 1000.0)
    rates = measure_line_rates(bands, whole.t_s, whole.range_m, geo, S.af_config(min_lines=1))
    weight = rates.weight[near_first]
    assert rates.quality[near_first][1] > 0.5  # the quality floor would let it through
    assert weight[0] > 0 and weight[1] <= 0.01 * weight[0], weight


def test_a_line_lit_in_one_look_only_gets_no_weight() -> None:
    """Two targets at 10 dB per pulse and no motion over a 0.4 s subaperture: one entering
    the beam a quarter in (in both of map drift's halves), one lit in the last fifth only
    (in the second half alone, 20 dB stronger: its range sidelobes are lines too). Their
    illumination balances are both under 0.05; the one-look line's half balance is under
    0.1 and its weight zero, the other's is kept, and with fewer than ``min_lines`` usable
    lines, none lit throughout, the subaperture makes no estimate of its own."""
    syn = S.make(0.4, [], snr_db=10.0)
    m = syn.t_s.size
    entering = S.make(0.4, [S.ground_target(0.0, 950.0)]).rc
    entering[: m // 4] = 0.0
    late = 10.0 * S.make(0.4, [S.ground_target(1.0, 1050.0)]).rc
    late[: 4 * m // 5] = 0.0
    config = S.af_config()
    bands = select_bands(syn.rc + entering + late, syn.range_m, config)
    lines = [int(np.argmin(np.abs(syn.range_m[bands.bins] - r))) for r in (950.0, 1050.0)]
    assert np.all(bands.balance[lines] < 0.05), bands.balance
    halves = bands.halves[lines]
    assert halves[0] > 0.4 and halves[1] < 0.05, halves
    geo = AutofocusGeometry(S.WAVELENGTH_M, S.SPEED_MPS, S.DEPTH_M, 1000.0)
    rates = measure_line_rates(bands, syn.t_s, syn.range_m, geo, S.af_config(min_lines=1))
    assert np.all(rates.peak_db[lines] >= config.min_peak_db), rates.peak_db
    assert np.all(rates.quality[lines] >= config.min_quality), rates.quality
    weight = rates.weight[lines]
    assert weight[0] > 0 and weight[1] == 0.0, weight
    # the halves decide, not the balance's square (which leaves such a line a weight that
    # depends on the noise in its empty quarters): counted as lit throughout, still zero
    lit = dataclasses.replace(bands, balance=np.ones_like(bands.balance))
    rates = measure_line_rates(lit, syn.t_s, syn.range_m, geo, config)
    assert rates.weight[lines[0]] > 0 and rates.weight[lines[1]] == 0.0, rates.weight
    assert abs(rates.rate_hz_per_s[lines[1]]) > 10.0, rates.rate_hz_per_s
    assert measure_line_rates(bands, syn.t_s, syn.range_m, geo, config).n_used == 0
