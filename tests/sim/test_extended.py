"""The extended demo scene: terrain-shaded clutter and corner reflectors, and its echoes."""

from __future__ import annotations

import numpy as np
import pytest

from sarmoco.errors import ConfigError
from sarmoco.sim.echo import synthesize
from sarmoco.sim.extended import (
    CLUTTER_AMPLITUDE,
    REFLECTORS,
    clutter_echo,
    extended_scenario,
    hillshade,
    load_scene,
)
from sarmoco.sim.scenario import Clutter, load_preset


def test_scene_lies_in_the_swath_with_its_reflectors() -> None:
    scn = extended_scenario("ku-vehicle", 0.1)
    c = scn.clutter
    assert c is not None
    ground_c = scn.scene_center_ned[1]
    assert np.all(np.abs(c.pos_ned[:, 1] - ground_c) <= scn.swath_m / 2)
    assert np.all(np.abs(c.pos_ned[:, 0]) <= scn.swath_m / 2) and np.all(c.pos_ned[:, 2] == 0)
    assert np.allclose(np.diff(c.x_m), scn.azimuth_resolution_m)
    assert c.reflectivity.shape == (c.x_m.size, c.y_m.size)
    assert 0.0 <= c.reflectivity.min() < 0.05 and c.reflectivity.max() > 0.9
    power = np.abs(c.amplitude.reshape(c.reflectivity.shape)) ** 2
    np.testing.assert_allclose(power, CLUTTER_AMPLITUDE**2 * c.reflectivity, rtol=1e-9)
    tgt, amp = scn.targets_array()
    assert tgt.shape == (len(REFLECTORS), 3) and np.abs(amp).max() == pytest.approx(1.4)
    # the aperture covers the whole patch: every scatterer is lit for a full beam
    t = np.arange(scn.n_pulses) / scn.radar.prf_hz
    apc, _ = scn.ideal_track(t)
    lit = scn.illumination(apc, c.pos_ned[::97])
    assert np.all(lit[0] == 0) and np.all(lit[-1] == 0)


def test_hillshade_is_the_terrain_not_noise() -> None:
    """Neighbouring cells of the shaded relief are alike (a picture), unlike white noise."""
    shade = hillshade((120, 120))
    a, b = shade[:, :-1].ravel(), shade[:, 1:].ravel()
    assert np.corrcoef(a, b)[0, 1] > 0.5


def test_clutter_echo_matches_the_exact_point_synthesis() -> None:
    """Binning to a delay grid 8x finer than the samples: the same echo as the closed form
    of sarmoco.sim.echo to the envelope's rounding (range within 1 cm)."""
    scn = extended_scenario("ku-vehicle", 0.1)
    c = scn.clutter
    assert c is not None
    apc, _ = scn.ideal_track(np.arange(0, scn.n_pulses, 5) / scn.radar.prf_hz)
    pick = np.random.default_rng(3).choice(c.amplitude.size, 60, replace=False)
    few = Clutter(c.pos_ned[pick], c.amplitude[pick], c.x_m, c.y_m, c.reflectivity)
    half = scn.integration_angle_rad / 2.0
    fast = clutter_echo(scn.radar, apc, few, scn.track_to_ned[:, 0], half)
    exact = synthesize(
        scn.radar, np.zeros(apc.shape[0], dtype=np.int64), apc, few.pos_ned, few.amplitude,
        None, np.random.default_rng(0), illumination=scn.illumination(apc, few.pos_ned),
    )  # fmt: skip
    assert np.linalg.norm(exact) > 0
    err = float(np.linalg.norm(fast - exact) / np.linalg.norm(exact))
    coherence = abs(np.vdot(fast, exact)) / (np.linalg.norm(fast) * np.linalg.norm(exact))
    print(f"clutter synthesis: relative error {err:.4f}, coherence {coherence:.5f}")
    assert err < 0.08 and coherence > 0.996


def test_scene_errors_name_the_key() -> None:
    with pytest.raises(ConfigError, match=r"scenario\.scene"):
        load_scene("forest", "ku-vehicle", 0.1)
    with pytest.raises(ConfigError, match=r"scenario\.receive"):
        load_scene("extended", "thz-spotlight", 0.1)
    with pytest.raises(ConfigError, match=r"scenario\.targets"):
        extended_scenario("ku-vehicle", 0.1, targets=())
    assert load_scene("points", "ku-vehicle", 0.1) == load_preset("ku-vehicle", 0.1)
    scn = load_preset("thz-spotlight", 0.1)
    dummy = Clutter(
        np.zeros((1, 3)), np.ones(1, complex), np.zeros(1), np.zeros(1), np.ones((1, 1))
    )
    with pytest.raises(ConfigError, match=r"radar\.receive"):
        clutter_echo(scn.radar, np.zeros((1, 3)), dummy, np.array([1.0, 0, 0]), None)
