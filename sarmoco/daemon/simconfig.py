"""Daemon configurations that match a simulated scenario (demo, tests, ``sim --out``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import tomli_w

from sarmoco.daemon.config import Config, parse_config
from sarmoco.sim.scenario import Scenario

TILE_LENGTH_M = 10.0
"""Along-track tile length used for simulated scenes, m."""


def config_table(scn: Scenario, **sections: dict[str, Any]) -> dict[str, Any]:
    """A configuration table (what TOML parses to) for the radar and geometry of ``scn``.

    Parameters
    ----------
    scn : Scenario
        The simulated scenario.
    **sections : dict
        Keys to set or override per section, e.g. ``ins={"protocol": "sbg"}``.
    """
    r = scn.radar
    table: dict[str, dict[str, Any]] = {
        "radar": {
            "carrier_hz": r.carrier_hz,
            "bandwidth_hz": r.bandwidth_hz,
            "pulse_width_s": r.pulse_width_s,
            "sample_rate_hz": r.sample_rate_hz,
            "prf_hz": r.prf_hz,
            "n_samples": r.n_samples,
            "range_gate_delay_s": r.range_gate_delay_s,
            "receive": r.receive,
        },
        "geometry": {"height_m": scn.altitude_m, "center_slant_range_m": scn.center_slant_range_m},
        "imaging": {
            "swath_m": 1.1 * scn.swath_m,
            "tile_length_m": TILE_LENGTH_M,
            "pixel_m": 0.5 * scn.azimuth_resolution_m,
            "azimuth_beamwidth_deg": math.degrees(scn.integration_angle_rad),
        },
    }
    for name, values in sections.items():
        table.setdefault(name, {}).update(values)
    return table


def scenario_config(scn: Scenario, **sections: dict[str, Any]) -> Config:
    """The validated :class:`Config` of :func:`config_table`."""
    return parse_config(config_table(scn, **sections))


def write_config(path: Path, table: dict[str, Any]) -> Path:
    """Validate ``table`` and write it as a TOML file; returns ``path``."""
    parse_config(table)
    path.write_text(
        "# sarmoco configuration matching a simulated scenario (written by sarmoco)\n"
        + tomli_w.dumps(table)
    )
    return path
