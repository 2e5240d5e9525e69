"""Configuration loading: defaults, the example file, and error messages."""

from __future__ import annotations

import dataclasses
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.simconfig import config_table, scenario_config
from sarmoco.daemon.config import (
    AutofocusSection,
    RadarConfig,
    describe_keys,
    keys_markdown,
    load_config,
    parse_config,
)
from sarmoco.daemon.focuser import Focuser, tile_imaging
from sarmoco.errors import ConfigError, ProcessingError
from sarmoco.processing.autofocus.settings import AutofocusConfig
from sarmoco.processing.imaging.tile_pga import TilePgaConfig
from sarmoco.processing.rangecomp import range_axis_m
from sarmoco.processing.types import RadarParams
from sarmoco.sim.scenario import load_preset
from tests.daemon.refusals import assert_refused


def test_example_config_loads(repo_root: Path) -> None:
    cfg = load_config(repo_root / "systemd" / "sarmoco.toml")
    assert cfg.radar.carrier_hz == 15.0e9
    assert cfg.ins.lever_arm_m == (0.10, 0.35, -0.05)
    assert cfg.autofocus.estimator == "map-drift"


def _documented_defaults() -> dict[str, dict[str, object]]:
    """The default column of :func:`describe_keys` (docs/configuration.md), parsed as TOML; a key
    whose default is "unset" is left out, as a user leaves it out."""
    table: dict[str, dict[str, object]] = {}
    for row in describe_keys():
        section, key = row["key"].split(".")
        if row["default"] == "unset":
            continue
        table.setdefault(section, {})[key] = tomllib.loads(f"v = {row['default']}")["v"]
    return table


def test_empty_table_gives_documented_defaults() -> None:
    """An empty file and a file that writes out every documented default give one config."""
    cfg = parse_config({})
    assert parse_config(_documented_defaults()) == cfg
    assert isinstance(cfg.radar.prf_hz, float)


def test_config_is_frozen() -> None:
    cfg = parse_config({})
    with pytest.raises(AttributeError):
        cfg.radar.prf_hz = 1.0  # type: ignore[misc]


def test_int_accepted_for_float_key() -> None:
    cfg = parse_config({"radar": {"prf_hz": 2000}})
    assert cfg.radar.prf_hz == 2000.0 and isinstance(cfg.radar.prf_hz, float)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"radar": {"prf_hz": -3}}, "radar.prf_hz: -3 is not > 0"),
        ({"radar": {"prf_hz": "fast"}}, "radar.prf_hz: 'fast' is not a number"),
        ({"radar": {"n_samples": 4.5}}, "radar.n_samples: 4.5 is not an integer"),
        ({"radar": {"prf": 1}}, "radar.prf: unknown key (allowed: "),
        (
            {"radar": {"receive": "fmcw"}},
            "radar.receive: 'fmcw' is not one of 'matched', 'dechirp'",
        ),
        ({"mocomp": {"order": 3}}, "mocomp.order: 3 is not one of 2"),
        (
            {"mocomp": {"order": 1}},
            "mocomp.order: 1 is refused: the scene-centre look angle for every bin leaves a "
            "look-angle error across the swath",
        ),
        ({"ins": {"lever_arm_m": [1, 2]}}, "ins.lever_arm_m: [1, 2] is not a list of 3 numbers"),
        ({"ins": {"lever_arm_m": [1, 2, "x"]}}, "ins.lever_arm_m[2]: 'x' is not a number"),
        ({"autofocus": {"enabled": 1}}, "autofocus.enabled: 1 is not true or false"),
        ({"autofocus": {"min_quality": 2}}, "autofocus.min_quality: 2 is not <= 1"),
        (
            {"autofocus": {"subaperture_s": 0.2, "hop_s": 0.3}},
            "autofocus: AutofocusConfig.hop_s: 0.3 must be in (0, subaperture_s 0.2]",
        ),
        (
            {"imaging": {"azimuth_beamwidth_deg": 90}},
            "imaging.azimuth_beamwidth_deg: 90 is not < 90",
        ),
        ({"status": {"http_port": 70000}}, "status.http_port: 70000 is not <= 65535"),
        ({"radar": 5}, "radar: 5 is not a table"),
        ({"rader": {}}, "rader: unknown key"),
    ],
)
def test_errors_name_key_value_and_rule(table: dict[str, object], message: str) -> None:
    assert_refused(table, message)


def test_config_error_is_a_value_error() -> None:
    with pytest.raises(ValueError, match=r"radar\.prf_hz"):
        parse_config({"radar": {"prf_hz": 0}})


def test_bad_files(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[radar\nprf_hz = 1\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")


def test_every_key_is_documented() -> None:
    rows = describe_keys()
    assert len(rows) > 30
    for row in rows:
        assert row["doc"], row["key"]


def test_key_table_rows_keep_their_cells() -> None:
    """A ``|`` in a key's meaning (``|d_los|``) must not split its row of the table."""
    lines = keys_markdown().splitlines()
    assert any("\\|" in line for line in lines)  # some meaning holds a |, escaped
    for line in lines:
        assert len(re.findall(r"(?<!\\)\|", line)) == 7, line


@pytest.mark.parametrize(
    ("table", "message"),
    [
        (
            {"geometry": {"height_m": 900.0, "center_slant_range_m": 900.0}},
            "geometry.center_slant_range_m: 900.0 m is not > geometry.height_m 900.0 m",
        ),
        (
            {"geometry": {"height_m": 800.0}},
            "radar.range_gate_delay_s: 5e-06 s starts the range window 749.48 .. 1363.31 m "
            "(radar.range_gate_delay_s 5e-06 s, radar.n_samples 4096, radar.sample_rate_hz "
            "1000000000.0 Hz, radar.receive 'matched') inside the nadir range "
            "geometry.height_m 800.0 m (no ground at those ranges); raise it to at least "
            "5.337e-06 s, or check geometry.height_m",
        ),
        (
            {"radar": {"receive": "dechirp"}},
            "radar.range_gate_delay_s: 5e-06 s starts the range window -249.83 .. 1748.30 m "
            "(radar.range_gate_delay_s 5e-06 s, radar.n_samples 4096, radar.sample_rate_hz "
            "1000000000.0 Hz, radar.receive 'dechirp') inside the nadir range geometry.height_m "
            "100.0 m (no ground at those ranges); the dechirp window reaches c f_s / 4K = "
            "999.31 m either side of the reference: lower radar.sample_rate_hz (decimate), or "
            "check geometry.height_m",
        ),
        (
            {"geometry": {"center_slant_range_m": 1400.0}},
            "geometry.center_slant_range_m: 1400.0 m is outside the range window 749.48 .. "
            "1363.31 m (radar.range_gate_delay_s 5e-06 s, radar.n_samples 4096",
        ),
        (
            {"imaging": {"swath_m": 400.0}},
            "imaging.swath_m: 400.0 m about geometry.center_slant_range_m 900.0 m spans slant "
            "ranges 701.59 .. 1098.99 m, outside the range window 749.48 .. 1363.31 m",
        ),
        (
            {"imaging": {"swath_m": 1800.0}},
            "imaging.swath_m: 1800.0 m reaches past nadir (the scene centre's ground range is "
            "894.43 m: geometry.center_slant_range_m 900.0 m, geometry.height_m 100.0 m)",
        ),
        (
            {"radar": {"receive": "dechirp", "range_gate_delay_s": 6e-6, "pulse_width_s": 1e-7}},
            "imaging.swath_m: 60.0 m about geometry.center_slant_range_m 900.0 m spans slant "
            "ranges 870.19 .. 929.82 m, outside the range window 889.38 .. 909.37 m "
            "(radar.range_gate_delay_s 6e-06 s, radar.n_samples 4096, radar.sample_rate_hz "
            "1000000000.0 Hz, radar.receive 'dechirp')",
        ),
        (
            {"radar": {"channels": 2}},
            "radar.channels: 2: single mode focuses one channel (each channel would need its "
            "own aperture and image set); set radar.channels = 1: the daemon focuses the VITA "
            "stream radar.stream_id and counts and skips the packets of other stream IDs; or "
            'radar.mode = "array" for a MIMO array (channels = array.n_tx * array.n_rx)',
        ),
    ],
    ids=[
        "centre-at-nadir",
        "gate-inside-nadir",
        "dechirp-window-inside-nadir",
        "centre-outside",
        "swath-outside",
        "swath-past-nadir",
        "dechirp-window",
        "channels",
    ],
)
def test_geometry_that_cannot_be_imaged_is_refused(table: dict[str, object], message: str) -> None:
    assert_refused(table, message)


@pytest.mark.parametrize("receive", ["matched", "dechirp"])
def test_slant_window_is_the_range_axis(receive: str) -> None:
    cfg = parse_config(
        {
            "radar": {"receive": receive, "n_samples": 1000, "pulse_width_s": 4e-6},
            "geometry": {"center_slant_range_m": 800.0},
            "imaging": {"swath_m": 10.0},
        }
    )
    axis = range_axis_m(cfg.radar.params())
    assert cfg.radar.slant_window_m() == pytest.approx((axis[0], axis[-1]), abs=1e-9)


def test_gate_inside_nadir_refused_before_geometry_code_crashes() -> None:
    """A ku-microuav x0.1 config with the platform 1990 m up: its range window starts at
    1981 m. Unchecked, the focuser dies in the look-angle geometry; the config check refuses
    it first, naming the gate and the height."""
    table = config_table(load_preset("ku-microuav", 0.1), geometry={"height_m": 1990.0})
    with pytest.raises(ConfigError, match=r"^radar\.range_gate_delay_s: .* inside the nadir "
                       r"range geometry\.height_m 1990\.0 m"):  # fmt: skip
        parse_config(table)
    good = parse_config(config_table(load_preset("ku-microuav", 0.1)))
    unchecked = dataclasses.replace(
        good, geometry=dataclasses.replace(good.geometry, height_m=1990.0)
    )
    with pytest.raises(ProcessingError, match=r"look_angle: slant range 1981\.0"):
        Focuser(unchecked, 0, np.array([25.0, 0.0, 0.0]))


@pytest.mark.parametrize(("direction", "conjugate"), [("up", False), ("down", True)])
def test_radar_conventions_reach_the_range_compression(direction: str, conjugate: bool) -> None:
    """simconfig writes the scenario's chirp direction and I/Q sign; the daemon's RadarParams
    are then exactly the simulator's."""
    scn = load_preset("ku-vehicle", 0.1, chirp_direction=direction, iq_conjugate=conjugate)
    cfg = scenario_config(scn)
    assert (cfg.radar.chirp_direction, cfg.radar.iq_conjugate) == (direction, conjugate)
    assert cfg.radar.params() == scn.radar


def test_a_section_of_a_processing_stage_is_that_stage_s_settings() -> None:
    """The ``radar`` section is the physics' radar description (RadarParams) plus the
    link's keys, and the ``autofocus`` section the autofocus and tile PGA settings plus the
    daemon's switches: each key is declared once, by the class that uses it, and reaches it
    untranslated (a key redeclared in the daemon could take another default)."""
    sections = (
        (RadarConfig, RadarParams),
        (AutofocusSection, AutofocusConfig),
        (AutofocusSection, TilePgaConfig),
    )
    for section, stage in sections:
        assert issubclass(section, stage), (section, stage)
        for f in dataclasses.fields(stage):
            assert f.name not in vars(section).get("__annotations__", {}), f.name
    cfg = parse_config({"radar": {"carrier_hz": 9.6e9, "chirp_direction": "down", "link": "r.vrt"},
                        "autofocus": {"pga": True, "pga_window_m": 7.0}})  # fmt: skip
    radar = cfg.radar.params()
    assert type(radar) is RadarParams
    assert radar == RadarParams(carrier_hz=9.6e9, chirp_direction="down")
    _, tile_pga = tile_imaging(cfg, radar)
    assert tile_pga is not None and tile_pga.pga.settings.pga_window_m == 7.0
