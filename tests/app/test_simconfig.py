"""Daemon configurations for simulated scenarios (:mod:`sarmoco.app.simconfig`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from sarmoco.app.simarray import array_config_table
from sarmoco.app.simconfig import (
    MIN_SUBAPERTURE_PULSES,
    autofocus_table,
    config_table,
    scenario_config,
    synthetic_aperture_s,
    write_config,
)
from sarmoco.daemon.config import load_config, parse_config
from sarmoco.errors import ConfigError
from sarmoco.sim.array_scenario import load_array_preset
from sarmoco.sim.scenario import load_preset


@pytest.mark.parametrize("preset", ["ku-vehicle", "ku-microuav", "thz-spotlight"])
def test_simconfig_fits_the_subapertures_into_the_synthetic_aperture(preset: str) -> None:
    scn = load_preset(preset, 1.0)
    t_sa = synthetic_aperture_s(scn)
    af = scenario_config(scn).autofocus
    assert af.enabled
    assert 2 * af.subaperture_s <= t_sa and af.subaperture_s <= 0.4
    assert af.subaperture_s * scn.radar.prf_hz >= MIN_SUBAPERTURE_PULSES
    assert af.hop_s == pytest.approx(af.subaperture_s / 4)  # the default overlap
    if preset.startswith("ku"):
        assert (af.subaperture_s, af.hop_s) == (0.4, 0.1)  # the defaults fit: unchanged
    else:
        assert t_sa == pytest.approx(scn.aperture_s)  # spotlight: the whole aperture
        assert af.subaperture_s == pytest.approx(t_sa / 4)
    slow = dataclasses.replace(scn, radar=dataclasses.replace(scn.radar, prf_hz=300.0))
    if 2 * MIN_SUBAPERTURE_PULSES / 300.0 > t_sa:  # two subapertures do not fit: off
        assert autofocus_table(slow) == {"enabled": False}
        assert not scenario_config(slow).autofocus.enabled


def test_the_written_file_loads_as_the_scenario_config(tmp_path: Path) -> None:
    scn = load_preset("ku-vehicle", 0.1)
    ins = {"protocol": "sbg", "link": "/dev/ttyS0"}
    path = write_config(tmp_path / "s.toml", config_table(scn, ins=ins))
    cfg = load_config(path)
    assert cfg == scenario_config(scn, ins=ins)
    assert (cfg.ins.protocol, cfg.ins.link) == ("sbg", "/dev/ttyS0")
    assert cfg.radar.prf_hz == scn.radar.prf_hz and cfg.radar.n_samples == scn.radar.n_samples
    assert cfg.geometry.center_slant_range_m == scn.center_slant_range_m


def test_an_invalid_table_is_not_written(tmp_path: Path) -> None:
    table = config_table(load_preset("ku-vehicle", 0.1), ins={"protocol": "nmea"})
    with pytest.raises(ConfigError, match=r"^ins\.protocol: 'nmea' is not one of"):
        write_config(tmp_path / "bad.toml", table)
    assert not (tmp_path / "bad.toml").exists()


def test_both_scenario_kinds_configure_the_scenarios_radar(tmp_path: Path) -> None:
    """The one radar table (``sim.scenario.radar_table``) carries every waveform key."""
    scn = load_preset("ku-vehicle", 0.1)
    odd = dataclasses.replace(
        scn.radar, receive="dechirp", chirp_direction="down", iq_conjugate=True
    )
    scn = dataclasses.replace(scn, radar=odd)
    assert scenario_config(scn).radar.params() == odd
    array = load_array_preset(0.1)
    cfg = parse_config(array_config_table(array, tmp_path, "float32"))
    assert cfg.radar.params() == array.radar
    assert (cfg.radar.mode, cfg.radar.channels) == ("array", array.layout.n_channels)
    assert cfg.radar.link == str(tmp_path / "radar.vrt")
    assert array.truth_dict()["radar"] == dataclasses.asdict(array.radar)
