"""Echo synthesis: exact closed form per sample, noise level, illumination, scene speed."""

from __future__ import annotations

import time

import numpy as np
import pytest

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import C_MPS, RadarParams
from sarmoco.sim.echo import noise_sigma, synthesize
from sarmoco.sim.scenario import load_preset, scene_targets


def _reference_sample(radar: RadarParams, n: np.ndarray, r: float) -> np.ndarray:
    """The module docstring's formulas, written independently with numpy."""
    k, tp, fs = radar.chirp_rate_hz_per_s, radar.pulse_width_s, radar.sample_rate_hz
    tau_d = 2 * r / C_MPS
    if radar.receive == "matched":
        tau = radar.range_gate_delay_s + n / fs
        on = (tau - tau_d >= 0) & (tau - tau_d < tp)
        ph = np.pi * k * (tau - tau_d - tp / 2) ** 2 - 4 * np.pi * r / radar.wavelength_m
        return np.where(on, np.exp(1j * ph), 0)
    delta = tau_d - radar.range_gate_delay_s
    u = (n - radar.n_samples // 2) / fs
    on = (u >= delta - tp / 2) & (u < delta + tp / 2)
    ph = -2 * np.pi * radar.carrier_hz * delta - 2 * np.pi * k * delta * u + np.pi * k * delta**2
    return np.where(on, np.exp(1j * ph), 0)


@pytest.mark.parametrize(
    ("name", "receive"), [("ku-vehicle", "matched"), ("thz-spotlight", "dechirp")]
)
def test_samples_match_closed_form(name: str, receive: str) -> None:
    radar = load_preset(name, scale=0.1, receive=receive).radar
    apc = np.array([[3.0, -1.0, -200.0], [3.5, -0.9, -200.1]])
    tgt = np.array([[10.0, radar.near_range_m + 0.3, 0.0]])
    if receive == "matched":
        tgt[0, 1] += 15.0
    r = np.linalg.norm(tgt[0] - apc, axis=1)
    echo = synthesize(
        radar,
        np.arange(2, dtype=np.int64),
        apc,
        tgt,
        np.array([0.7 - 0.2j]),
        None,
        np.random.default_rng(0),
    )
    n = np.arange(radar.n_samples)
    for p in range(2):
        want = (0.7 - 0.2j) * _reference_sample(radar, n, float(r[p]))
        assert np.count_nonzero(want) > 0.5 * radar.pulse_width_s * radar.sample_rate_hz
        np.testing.assert_allclose(echo[p], want, atol=2e-6)


def test_noise_level_and_illumination() -> None:
    radar = load_preset("ku-vehicle", scale=0.1).radar
    apc = np.zeros((64, 3))
    tgt = np.array([[0.0, radar.near_range_m + 10.0, 0.0]])
    for snr in (0.0, 10.0):
        echo = synthesize(
            radar,
            np.arange(64, dtype=np.int64),
            apc,
            tgt,
            np.zeros(1),
            snr,
            np.random.default_rng(1),
        )
        assert np.var(echo) == pytest.approx(noise_sigma(snr) ** 2, rel=0.03)
        assert abs(np.mean(echo.real * echo.imag)) < 0.02 * noise_sigma(snr) ** 2
    lit = np.zeros((64, 1))
    lit[10] = 1.0
    echo = synthesize(
        radar,
        np.arange(64, dtype=np.int64),
        apc,
        tgt,
        np.ones(1),
        None,
        np.random.default_rng(1),
        illumination=lit,
    )
    assert np.count_nonzero(np.abs(echo).sum(1)) == 1 and np.abs(echo[10]).max() == pytest.approx(
        1.0
    )


@pytest.mark.parametrize(
    ("n_times", "n_targets"),
    [(3, 1), (2, 2)],
    ids=["times-vs-positions", "targets-vs-amplitudes"],
)
def test_shapes_checked(n_times: int, n_targets: int) -> None:
    """Two pulse positions with 3 pulse times, or 2 targets with 1 amplitude, are refused."""
    radar = load_preset("ku-vehicle", scale=0.1).radar
    with pytest.raises(ProcessingError):
        synthesize(
            radar,
            np.arange(n_times, dtype=np.int64),
            np.zeros((2, 3)),
            np.zeros((n_targets, 3)),
            np.ones(1),
            None,
            np.random.default_rng(),
        )


def test_scene_of_300_scatterers() -> None:
    """300 illuminated scatterers synthesise to one complex64 row per pulse (the time it
    takes is printed here and measured by ``python -m bench.bench_sim``, not asserted: a
    wall-clock bound in a unit test fails on a loaded machine)."""
    scn = load_preset("ku-vehicle", scale=0.1)
    rng = np.random.default_rng(5)
    targets = scene_targets(scn, 300, rng)
    tgt = np.array([t.pos_ned for t in targets])
    amp = np.array([t.amplitude for t in targets])
    t = np.arange(scn.n_pulses) / scn.radar.prf_hz
    apc, _ = scn.ideal_track(t)
    lit = scn.illumination(apc, tgt)
    t0 = time.perf_counter()
    echo = synthesize(
        scn.radar, np.arange(t.size, dtype=np.int64), apc, tgt, amp, 0.0, rng, illumination=lit
    )
    elapsed = time.perf_counter() - t0
    print(f"300 scatterers x {scn.n_pulses} pulses synthesised in {elapsed:.2f} s")
    assert echo.shape == (scn.n_pulses, scn.radar.n_samples) and echo.dtype == np.complex64
    assert np.count_nonzero(np.abs(echo).max(axis=1) > 0) == int(lit.any(axis=1).sum())
