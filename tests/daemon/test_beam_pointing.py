"""Which squints the pixels take before and after a segment's echoes show where the beam is.

The focuser's beam of a ku-vehicle-like geometry (λ = 2 cm, v = 17.5 m/s, beam 2.86°),
pointed by an attitude whose heading is 1.5° off the track, and told the echoes' Doppler
by pulses that carry one Doppler frequency in every range bin (the Madsen correlation
then reads it exactly).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.config import Config
from sarmoco.daemon.focuser import MIN_COHERENCE, Focuser, _Beam
from sarmoco.processing.beam import accc_coherence, accc_correlation, doppler_hz
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.trajectory import euler_to_quat

T0_NS = 10**18
SPEED_MPS = 17.5
YAW_OFF_DEG = 1.5
"""The attitude's heading against the track (and the beam, which stays broadside), deg."""


def _beam(prf_hz: float | None = None, uncertainty_deg: float = 2.0) -> tuple[_Beam, Config]:
    """The first segment's beam of a focuser on a northbound track."""
    scn = load_preset("ku-vehicle", 0.1, snr_db=None, **({"prf_hz": prf_hz} if prf_hz else {}))
    cfg = scenario_config(scn, imaging={"pointing_uncertainty_deg": uncertainty_deg})
    focuser = Focuser(cfg, T0_NS, np.array([SPEED_MPS, 0.0, 0.0]))
    assert focuser.segment is not None
    return focuser.segment.beam, cfg


def _yawed(n: int) -> np.ndarray:
    return euler_to_quat(np.tile([0.0, 0.0, math.radians(YAW_OFF_DEG)], (n, 1)))


def _echoes_at(f_hz: float, prf_hz: float, n: int = 256) -> np.ndarray:
    """Range-compressed pulses holding one Doppler frequency in every bin."""
    phase = np.exp(2j * np.pi * f_hz * np.arange(n) / prf_hz)
    return np.outer(phase, np.ones(64)).astype(np.complex64)


def test_until_the_echoes_show_the_beam_the_pixels_take_the_pointing_uncertainty() -> None:
    trusted, cfg = _beam(1000.0, 0.0)  # a pulse rate with room for the widening
    unsure, _ = _beam(1000.0)
    for beam in (trusted, unsure):
        beam.point(_yawed(8), T0_NS)
    lo0, hi0 = trusted.interval_at(np.array([T0_NS]))[0]
    lo, hi = unsure.interval_at(np.array([T0_NS]))[0]
    assert lo == pytest.approx(lo0 - math.radians(2.0), abs=1e-9)
    assert hi == pytest.approx(hi0 + math.radians(2.0), abs=1e-9)
    half = math.radians(cfg.imaging.azimuth_beamwidth_deg) / 2.0
    assert hi0 < half  # the attitude alone cuts the front edge of the beam (broadside) off
    assert lo < -half < half < hi  # the uncertainty's beam holds it
    # the echoes show the beam broadside (0 Hz): from the next block on, the pixels take
    # the attitude's beam and the beam about the echoes' centroid, and no more
    prf = cfg.radar.prf_hz
    echoes = _echoes_at(0.0, prf)
    unsure.measure(echoes, T0_NS + np.arange(256) * round(1e9 / prf), prf)
    t1 = T0_NS + 10**9
    unsure.point(_yawed(8), t1)
    unsure.measure(echoes, t1 + np.arange(256) * round(1e9 / prf), prf)  # before imaging
    lo1, hi1 = unsure.interval_at(np.array([t1]))[0]
    assert lo1 == pytest.approx(lo0, abs=1e-9)
    assert hi1 == pytest.approx(hi0 + math.radians(YAW_OFF_DEG), abs=2e-3)


def test_the_uncertainty_keeps_the_band_within_the_pulse_rate() -> None:
    """At a pulse rate of 1.5 times the beam's Doppler band, 2° on each side would span
    more Doppler than the pulse rate: the widening stops at it."""
    probe, cfg = _beam()
    wavelength = cfg.radar.params().wavelength_m
    band = float(np.ptp(doppler_hz(SPEED_MPS, wavelength, probe.interval_at(np.array([T0_NS]))[0])))
    prf = 1.5 * band
    trusted, _ = _beam(prf, 0.0)
    unsure, _ = _beam(prf)
    for beam in (trusted, unsure):
        beam.point(_yawed(8), T0_NS)
    f0 = doppler_hz(SPEED_MPS, wavelength, trusted.interval_at(np.array([T0_NS]))[0])
    f = doppler_hz(SPEED_MPS, wavelength, unsure.interval_at(np.array([T0_NS]))[0])
    assert f[0] < f0[0] and f[1] > f0[1]  # widened
    assert np.ptp(f) == pytest.approx(prf, rel=1e-6)  # as far as the pulse rate


def test_a_block_of_noise_alone_takes_no_wider_beam() -> None:
    """A block whose echoes correlate too little for a centroid: noise alone is imaged over
    the attitude's beam (the wider one would add only noise, at about three times the
    imaging cost); a target entering the beam (8 of 128 pulses lit in one range bin, 20 dB
    over the noise; the echoes' coherence stays far below what a centroid needs) keeps the
    pointing uncertainty's beam."""
    rng = np.random.default_rng(1)
    trusted, cfg = _beam(1000.0, 0.0)
    noise_only, _ = _beam(1000.0)
    entering, _ = _beam(1000.0)
    prf = cfg.radar.prf_hz
    t_ns = T0_NS + np.arange(128) * round(1e9 / prf)
    shape = (128, 256)
    noise = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / math.sqrt(2.0)
    lit = noise.copy()
    lit[-8:, 100] += 10.0 * np.exp(2j * np.pi * 50.0 * np.arange(8) / prf)
    assert accc_coherence(lit, accc_correlation(lit)) < MIN_COHERENCE / 3
    for beam in (trusted, noise_only, entering):
        beam.point(_yawed(8), T0_NS)
    noise_only.measure(noise.astype(np.complex64), t_ns, prf)
    entering.measure(lit.astype(np.complex64), t_ns, prf)
    first = np.array([T0_NS])
    lo0, hi0 = trusted.interval_at(first)[0]
    np.testing.assert_allclose(noise_only.interval_at(first)[0], [lo0, hi0], atol=1e-12)
    lo, hi = entering.interval_at(first)[0]
    assert lo == pytest.approx(lo0 - math.radians(2.0), abs=1e-9)
    assert hi == pytest.approx(hi0 + math.radians(2.0), abs=1e-9)
