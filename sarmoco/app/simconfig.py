"""Daemon configurations that match a simulated scenario (demo, tests, ``sim --out``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import tomli_w

from sarmoco.daemon.config import Config, parse_config
from sarmoco.sim.scenario import Scenario, radar_table

TILE_LENGTH_M = 10.0
"""Along-track tile length used for simulated scenes, m."""
SUBAPERTURES_PER_APERTURE = 4.0
"""A simulated scene's autofocus subaperture is at most this fraction of its synthetic
aperture time (and never longer than :data:`MAX_SUBAPERTURE_S`)."""
MAX_SUBAPERTURE_S = 0.4
"""Longest autofocus subaperture of a simulated scene, s: the presets' figures on the
measurements pages were taken with it (the ``autofocus.subaperture_s`` default is chosen
on the independent acceptance flight)."""
HOPS_PER_SUBAPERTURE = 4.0
"""A simulated scene's hop is this fraction of its subaperture (75 % overlap)."""
MIN_SUBAPERTURE_PULSES = 32
"""Fewest pulses in a subaperture: the Doppler-rate estimators need some Doppler resolution."""

LIVE_METHOD = {"spotlight": "pfa", "stripmap": "method"}
"""``imaging.live_method`` of a simulated scene by its mode: the polar format live image for
spotlight; stripmap live runs keep ``imaging.method``."""


def synthetic_aperture_s(scn: Scenario) -> float:
    """Time the scene centre spends in the synthetic aperture, ``2 R_c tan(theta/2) / v``, s.

    Spotlight: the whole aperture; stripmap: the time a point stays in the beam.
    """
    half = math.tan(scn.integration_angle_rad / 2.0)
    return 2.0 * scn.center_slant_range_m * half / scn.speed_mps


def autofocus_table(scn: Scenario) -> dict[str, Any]:
    """``autofocus`` keys that fit the subapertures into the scene's synthetic aperture.

    The subaperture is :data:`MAX_SUBAPERTURE_S`, or a quarter of the synthetic aperture
    time when that is shorter (a ``thz-spotlight`` aperture is 0.12 s), but at least
    :data:`MIN_SUBAPERTURE_PULSES` at the PRF; the hop is a quarter of it
    (:data:`HOPS_PER_SUBAPERTURE`). When the aperture cannot hold two such subapertures
    the autofocus is switched off (INS-only focusing).

    Returns
    -------
    dict
        ``{"subaperture_s": ..., "hop_s": ...}`` or ``{"enabled": False}``.
    """
    aperture_s = synthetic_aperture_s(scn)
    sub_s = max(
        min(MAX_SUBAPERTURE_S, aperture_s / SUBAPERTURES_PER_APERTURE),
        MIN_SUBAPERTURE_PULSES / scn.radar.prf_hz,
    )
    if 2.0 * sub_s > aperture_s:
        return {"enabled": False}
    return {"subaperture_s": sub_s, "hop_s": sub_s / HOPS_PER_SUBAPERTURE}


def config_table(scn: Scenario, **sections: dict[str, Any]) -> dict[str, Any]:
    """A configuration table (what TOML parses to) for the radar and geometry of ``scn``.

    Parameters
    ----------
    scn : Scenario
        The simulated scenario.
    **sections : dict
        Keys to set or override per section, e.g. ``ins={"protocol": "sbg"}``.
    """
    table: dict[str, dict[str, Any]] = {
        "radar": radar_table(scn.radar),
        "geometry": {
            "height_m": scn.altitude_m,
            "center_slant_range_m": scn.center_slant_range_m,
            "look_side": scn.look_side,
        },
        "ins": {"lever_arm_m": list(scn.lever_arm_m)},
        "imaging": {
            "swath_m": 1.1 * scn.swath_m,
            "tile_length_m": TILE_LENGTH_M,
            "pixel_m": 0.5 * scn.azimuth_resolution_m,
            "azimuth_beamwidth_deg": math.degrees(scn.integration_angle_rad),
            "live_method": LIVE_METHOD[scn.mode],
        },
        "autofocus": autofocus_table(scn),
    }
    for name, values in sections.items():
        table.setdefault(name, {}).update(values)
    return table


def scenario_config(scn: Scenario, **sections: dict[str, Any]) -> Config:
    """The validated :class:`Config` of :func:`config_table`."""
    return parse_config(config_table(scn, **sections))


def write_config(path: Path, table: dict[str, Any]) -> Path:
    """Validate ``table`` and write it as a TOML file (unset keys left out); returns ``path``."""
    parse_config(table)
    written = {
        name: {k: v for k, v in section.items() if v is not None}
        if isinstance(section, dict)
        else section
        for name, section in table.items()
    }
    path.write_text(
        "# sarmoco configuration matching a simulated scenario (written by sarmoco)\n"
        + tomli_w.dumps(written)
    )
    return path


def loopback_config(
    out: Path,
    scn: Scenario,
    radar_link: str,
    ins: tuple[str, str],
    http_port: int,
    sections: dict[str, dict[str, Any]],
) -> Path:
    """Write ``out/sarmoco.toml`` for a daemon fed by a serving simulator on loopback.

    Parameters
    ----------
    out : Path
        Folder of the configuration and of the daemon's stores (``recorder.directory``).
    scn : Scenario
        The simulated scenario (radar, geometry, autofocus keys: :func:`config_table`).
    radar_link : str
        ``radar.link`` the simulator announced.
    ins : tuple of str
        ``ins.protocol`` and ``ins.link``.
    http_port : int
        ``status.http_port`` (0: any free port).
    sections : dict
        Extra keys per section, over the above.
    """
    table = config_table(
        scn,
        radar={"link": radar_link},
        ins={"protocol": ins[0], "link": ins[1]},
        recorder={"directory": str(out)},
        status={"http_port": http_port},
    )
    for name, values in sections.items():
        table.setdefault(name, {}).update(values)
    return write_config(out / "sarmoco.toml", table)
