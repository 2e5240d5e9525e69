"""Presets load, carry the papers' numbers (docs/methods.md §6) and scale without changing
physics."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest

from sarmoco.errors import ConfigError
from sarmoco.processing.types import C_MPS
from sarmoco.sim.array_scenario import load_array_preset
from sarmoco.sim.scenario import (
    _RADAR_KEYS,
    _SCENARIO_KEYS,
    PRESETS,
    PresetParams,
    Target,
    load_preset,
    scene_targets,
)


def test_thz_spotlight_is_the_papers_table_1() -> None:
    scn = load_preset("thz-spotlight")
    r = scn.radar
    assert (r.carrier_hz, r.bandwidth_hz, r.prf_hz, r.pulse_width_s) == (0.2e12, 1.1e9, 20e3, 10e-6)
    assert (scn.speed_mps, scn.altitude_m, scn.center_slant_range_m) == (60.0, 1000.0, 1500.0)
    assert scn.mode == "spotlight" and scn.swath_m == 130.0 and scn.snr_db == 10.0
    assert r.receive == "dechirp" and r.n_samples == 4096
    assert scn.azimuth_resolution_m == pytest.approx(0.16, rel=1e-6)
    # kept altitude and range, so grazing is 41.8 deg, not the paper's 30 deg
    assert math.degrees(scn.grazing_rad) == pytest.approx(41.81, abs=0.01)
    # the stated range window: +-210 m about 1500 m, bins of 0.106 m
    half_window = C_MPS * (r.n_samples / r.sample_rate_hz - r.pulse_width_s) / 4.0
    assert half_window == pytest.approx(210.0, abs=1.0)
    assert C_MPS * r.sample_rate_hz / (2 * r.chirp_rate_hz_per_s * r.n_samples) == pytest.approx(
        0.1064, abs=1e-3
    )


def test_ku_vehicle_is_the_papers_table_1() -> None:
    scn = load_preset("ku-vehicle")
    assert scn.radar.carrier_hz == 15e9  # our choice inside Ku
    assert scn.radar.range_resolution_m == pytest.approx(0.2, rel=1e-3)
    assert scn.azimuth_resolution_m == pytest.approx(0.2, rel=1e-6)
    assert (scn.speed_mps, scn.center_slant_range_m, scn.swath_m) == (17.5, 900.0, 300.0)
    assert scn.mode == "stripmap" and scn.radar.receive == "matched"


def test_ku_microuav() -> None:
    scn = load_preset("ku-microuav")
    assert (scn.speed_mps, scn.center_slant_range_m, scn.mode) == (25.0, 2000.0, "stripmap")
    assert math.degrees(scn.integration_angle_rad) == pytest.approx(3.0, abs=1e-4)


@pytest.mark.parametrize("name", PRESETS)
def test_scaled_keeps_physics(name: str) -> None:
    full, small = load_preset(name), load_preset(name, scale=0.1)
    for attr in ("carrier_hz", "bandwidth_hz", "sample_rate_hz", "receive"):
        assert getattr(full.radar, attr) == getattr(small.radar, attr)
    assert small.azimuth_resolution_m == full.azimuth_resolution_m
    assert small.radar.n_samples < full.radar.n_samples / 5
    assert small.radar.prf_hz <= full.radar.prf_hz and small.swath_m == pytest.approx(
        0.1 * full.swath_m
    )
    assert small.n_pulses * small.radar.n_samples < 2e6
    assert len(small.targets) == 3


@pytest.mark.parametrize("name", PRESETS)
def test_default_targets_near_centre_far_at_broadside(name: str) -> None:
    scn = load_preset(name, scale=0.2)
    tgt, amp = scn.targets_array()
    assert (
        np.all(np.diff(tgt[:, 1]) > 0) and np.allclose(tgt[:, 0], 0) and np.allclose(tgt[:, 2], 0)
    )
    assert tgt[1, 1] == pytest.approx(scn.scene_center_ned[1])
    assert np.allclose(amp, 1.0)
    # the scene centre is at broadside mid-aperture at the stated slant range
    mid, _ = scn.ideal_track(np.array([scn.aperture_s / 2]))
    assert np.linalg.norm(np.array(scn.scene_center_ned) - mid[0]) == pytest.approx(
        scn.center_slant_range_m
    )


def test_nominal_tracks_fly_level_above_the_ground() -> None:
    """Both scenario kinds' nominal tracks (one ``level_track``): at -altitude in NED
    (z down, the ground at 0), at the scenario's speed along the track."""
    t = np.linspace(0.0, 2.0, 5)
    scn = load_preset("ku-vehicle", scale=0.1, heading_rad=0.5)
    pos, vel = scn.ideal_track(t)
    np.testing.assert_allclose(pos[:, 2], -scn.altitude_m)
    np.testing.assert_allclose(vel, np.tile(scn.speed_mps * scn.track_to_ned[:, 0], (5, 1)))
    np.testing.assert_allclose(np.diff(pos, axis=0), vel[1:] * np.diff(t)[:, None])
    mimo = load_array_preset(0.1)
    array = mimo.trajectory(t)
    np.testing.assert_allclose(array.pos_ned[:, 2], -mimo.altitude_m)
    np.testing.assert_allclose(array.vel_ned, np.tile([mimo.speed_mps, 0.0, 0.0], (5, 1)))


def test_stripmap_illumination_spans_the_integration_angle() -> None:
    scn = load_preset("ku-vehicle", scale=0.1)
    t = np.arange(scn.n_pulses) / scn.radar.prf_hz
    apc, _ = scn.ideal_track(t)
    tgt, _ = scn.targets_array()
    lit = scn.illumination(apc, tgt)
    for k in range(tgt.shape[0]):
        seen = apc[lit[:, k] > 0]
        d0, d1 = tgt[k] - seen[0], tgt[k] - seen[-1]
        angle = math.atan2(d0[0], math.hypot(d0[1], d0[2])) - math.atan2(
            d1[0], math.hypot(d1[1], d1[2])
        )
        assert angle == pytest.approx(scn.integration_angle_rad, rel=0.02)


def test_overrides_and_errors() -> None:
    scn = load_preset(
        "ku-vehicle", scale=0.1, snr_db=None, prf_hz=300.0, targets=(Target((1.0, 898.0, 0.0)),)
    )
    assert scn.snr_db is None and scn.radar.prf_hz == 300.0 and len(scn.targets) == 1
    assert load_preset("ku-vehicle", scale=0.1, receive="dechirp").radar.receive == "dechirp"
    with pytest.raises(ConfigError):
        load_preset("no-such")
    with pytest.raises(ConfigError):
        load_preset("ku-vehicle", bogus=1)
    with pytest.raises(ConfigError):
        load_preset("ku-vehicle", scale=0.0)
    with pytest.raises(ConfigError):  # 320 MHz cannot sample a 1.1 GHz chirp
        load_preset("thz-spotlight", receive="matched")
    with pytest.raises(ConfigError):  # a 4096-sample dechirp window cannot hold a 3 km swath
        load_preset("thz-spotlight", swath_m=3000.0)


def test_every_override_key_is_a_preset_parameter() -> None:
    """The keys ``load_preset`` accepts as overrides are exactly the parameters' fields."""
    assert {f.name for f in fields(PresetParams)} == _RADAR_KEYS | _SCENARIO_KEYS


def test_scene_targets() -> None:
    scn = load_preset("ku-vehicle", scale=0.1)
    tg = scene_targets(scn, 300, np.random.default_rng(0))
    pos = np.array([t.pos_ned for t in tg])
    assert len(tg) == 300
    assert np.all(np.abs(pos[:, 1] - scn.scene_center_ned[1]) <= scn.swath_m / 2)
    assert np.mean([abs(t.amplitude) ** 2 for t in tg]) == pytest.approx(1.0, rel=0.2)


def test_approach_lengthens_the_track_before_the_targets() -> None:
    base = load_preset("ku-vehicle", 0.03)
    longer = load_preset("ku-vehicle", 0.03, approach_s=11.5)
    assert longer.radar == base.radar and longer.targets == base.targets
    assert longer.aperture_s == pytest.approx(base.aperture_s + 11.5)
    assert longer.track_start_north_m == pytest.approx(
        base.track_start_north_m - 11.5 * base.speed_mps
    )
    assert longer.n_pulses - base.n_pulses == pytest.approx(11.5 * base.radar.prf_hz, abs=1)
    with pytest.raises(ConfigError, match="approach_s"):
        load_preset("ku-vehicle", 0.03, approach_s=-1.0)
