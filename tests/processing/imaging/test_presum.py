"""The streaming azimuth pre-filter: design, tones, block independence, dropped pulses, gaps."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import signal

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.presum import ATTENUATION_DB, AzimuthPrefilter, kaiser_lowpass
from sarmoco.processing.types import ComplexArray, IntArray

PRF = 20_000.0
BAND = 206.0  # thz-spotlight: beam-limited Doppler of the culled beam, Hz
T0 = 1_400_000_000 * 10**9


def _times(n: int) -> IntArray:
    return T0 + np.rint(np.arange(n) * 1e9 / PRF).astype(np.int64)


def _tones(freqs: list[float], n: int) -> ComplexArray:
    t = np.arange(n) / PRF
    return np.stack([np.exp(2j * np.pi * f * t) for f in freqs], axis=1).astype(np.complex64)


def _run(
    f: AzimuthPrefilter, x: ComplexArray, t: IntArray, cuts: list[int]
) -> tuple[ComplexArray, IntArray]:
    """Push ``x`` in blocks split at ``cuts``, then flush; all outputs and their times."""
    edges = [0, *cuts, x.shape[0]]
    parts = [f.push(x[a:b], t[a:b]) for a, b in itertools.pairwise(edges)]
    parts.append(f.flush())
    data = [p[0] for p in parts if p[0].shape[0]]
    return np.concatenate(data), np.concatenate([p[1] for p in parts])


def test_design_passband_stopband() -> None:
    f = AzimuthPrefilter(PRF, BAND, oversampling=2.0)
    d = f.decimation
    assert d == int(PRF // (4 * BAND))
    taps = f.taps.astype(np.float64)
    assert taps.size % 2 == 1 and np.allclose(taps, taps[::-1]) and taps.sum() == pytest.approx(d)
    freq = np.linspace(0.0, PRF / 2, 8001)
    k = np.arange(taps.size) - (taps.size - 1) / 2
    gain = np.abs(np.exp(-2j * np.pi * freq[:, None] * k[None, :] / PRF) @ taps) / d
    passband = freq <= BAND
    stopband = freq >= PRF / d - BAND  # what folds onto the passband after decimation
    assert np.all(np.abs(gain[passband] - 1.0) <= 3e-3)  # 0.026 dB
    assert np.all(gain[stopband] <= 10 ** (-ATTENUATION_DB / 20))


@pytest.mark.parametrize(
    ("rate_hz", "pass_hz", "stop_hz", "attenuation_db"),
    [(PRF, BAND, PRF / 24 - BAND, ATTENUATION_DB), (200.0, 36.0, 64.0, 60.0),
     (1000.0, 100.0, 180.0, 40.0), (1000.0, 100.0, 150.0, 15.0)],
)  # fmt: skip
def test_kaiser_design_is_scipys(
    rate_hz: float, pass_hz: float, stop_hz: float, attenuation_db: float
) -> None:
    """The taps are those of ``scipy.signal.kaiserord`` and ``firwin`` (length made odd), in
    each of the three regimes of Kaiser's ``beta``."""
    n, beta = signal.kaiserord(attenuation_db, (stop_hz - pass_hz) / (rate_hz / 2))
    n += 1 - n % 2
    want = signal.firwin(n, (pass_hz + stop_hz) / 2, window=("kaiser", beta), fs=rate_hz)
    got = kaiser_lowpass(rate_hz, pass_hz, stop_hz, attenuation_db)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    with pytest.raises(ProcessingError, match="below the design's 8 dB"):
        kaiser_lowpass(rate_hz, pass_hz, stop_hz, 7.9)


def test_tones_in_and_out_of_band() -> None:
    """A passband tone comes out D times its sample at the output's centre slot, in phase."""
    f = AzimuthPrefilter(PRF, BAND, oversampling=2.0)
    n = 4000
    freqs = [0.0, 150.0, -BAND, PRF / f.decimation - BAND + 10.0, -3000.0]
    x, t = _tones(freqs, n), _times(n)
    y, t_out = _run(f, x, t, [1000])
    slot = (t_out - T0) * PRF / 1e9
    assert np.allclose(slot, np.round(slot), atol=1e-6)
    assert np.all(np.diff(slot) == f.decimation)
    inner = (slot >= f.delay_slots) & (slot < n - f.delay_slots)
    expect = f.decimation * np.exp(2j * np.pi * np.outer(slot[inner] / PRF, freqs[:3]))
    assert np.max(np.abs(y[inner, :3] / expect - 1.0)) < 3e-3
    assert np.max(np.abs(y[inner, 3:])) / f.decimation < 2e-3
    # the outputs cover every centre whose window reaches a pulse, at both ends
    assert slot[0] >= -f.delay_slots and slot[0] - f.decimation < -f.delay_slots
    assert slot[-1] <= n - 1 + f.delay_slots and slot[-1] + f.decimation > n - 1 + f.delay_slots


def test_blocks_do_not_change_the_output() -> None:
    rng = np.random.default_rng(3)
    n = 1500
    x = (rng.standard_normal((n, 5)) + 1j * rng.standard_normal((n, 5))).astype(np.complex64)
    t = _times(n)
    ref = _run(AzimuthPrefilter(PRF, BAND), x, t, [])
    for cuts in ([1], [7, 8, 9, 700], list(range(50, n, 97))):
        got = _run(AzimuthPrefilter(PRF, BAND), x, t, cuts)
        assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])


def test_dropped_pulses_are_zeros_in_their_slots() -> None:
    rng = np.random.default_rng(4)
    n = 1200
    x = (rng.standard_normal((n, 3)) + 1j * rng.standard_normal((n, 3))).astype(np.complex64)
    t = _times(n) + rng.integers(-2000, 2000, n)  # 2 us of timing jitter
    keep = np.ones(n, bool)
    keep[[5, 300, 301, 302, 900]] = False
    holes = x.copy()
    holes[~keep] = 0
    full = _run(AzimuthPrefilter(PRF, BAND), holes, t, [600])
    dropped = _run(AzimuthPrefilter(PRF, BAND), x[keep], t[keep], [600])
    assert np.allclose(dropped[0], full[0], atol=1e-5)
    assert np.all(np.abs(dropped[1] - full[1]) <= 2000)


def test_long_gap_starts_a_new_run() -> None:
    f = AzimuthPrefilter(PRF, BAND)
    n = 800
    x = _tones([40.0], 2 * n)
    t = _times(2 * n)
    t[n:] += 10**9  # one second without pulses
    both = _run(f, x, t, [n - 10])
    first = _run(AzimuthPrefilter(PRF, BAND), x[:n], t[:n], [])
    second = _run(AzimuthPrefilter(PRF, BAND), x[n:], t[n:], [])
    assert np.array_equal(both[0], np.concatenate([first[0], second[0]]))
    assert np.array_equal(both[1], np.concatenate([first[1], second[1]]))


def test_no_decimation_is_a_pass_through() -> None:
    f = AzimuthPrefilter(175.0, 54.7, oversampling=2.0)  # ku-vehicle at scale 0.1
    assert f.decimation == 1
    x = _tones([10.0], 20)
    y, t = f.push(x, _times(20))
    assert y is x and np.array_equal(t, _times(20))
    assert f.flush()[0].shape[0] == 0


def test_rejects_bad_input() -> None:
    with pytest.raises(ProcessingError):
        AzimuthPrefilter(PRF, BAND, oversampling=1.0)
    with pytest.raises(ProcessingError):
        AzimuthPrefilter(PRF, -1.0)
    f = AzimuthPrefilter(PRF, BAND)
    x = _tones([0.0], 4)
    with pytest.raises(ProcessingError):
        f.push(x, _times(4)[::-1].copy())
    with pytest.raises(ProcessingError):
        f.push(x, _times(3))
