"""A simulated run's truth (``truth.json``, written by ``sarmoco sim``) read for the report.

The report scores a run against what really happened when it is given it: the antenna's
true motion (:class:`~sarmoco.products.report.TrueMotion`) for a single-channel run, the
true terrain (:class:`~sarmoco.products.array_report.TrueTerrain`) for an array run. The
simulator's record holds the pulses as they were synthesised, on the simulator's clock;
``wire.shift_ns`` is what was added to every time on the wire (0 for files; a live run
played in real time is put *now*), so the truth's times plus it are the store's.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.errors import DataFileError, RecorderError
from sarmoco.products.array_report import TrueTerrain
from sarmoco.products.report import TrueMotion


def read_true_motion(path: Path) -> TrueMotion:
    """The true APC velocity per pulse of a simulated run, on the store's GPS time base.

    Parameters
    ----------
    path : Path
        The run's ``truth.json`` (``pulses.t_ns``, ``pulses.vel_ned`` NED m/s,
        ``wire.shift_ns``).

    Raises
    ------
    RecorderError
        Unreadable, not JSON, or without those keys.
    """
    try:
        truth = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise RecorderError(f"{path}: not a simulator truth record ({exc})") from exc
    pulses = truth.get("pulses") if isinstance(truth, dict) else None
    wire = truth.get("wire") if isinstance(truth, dict) else None
    if not (isinstance(pulses, dict) and {"t_ns", "vel_ned"} <= pulses.keys()
            and isinstance(wire, dict) and "shift_ns" in wire):  # fmt: skip
        raise RecorderError(
            f"{path}: not a simulator truth record (pulses.t_ns, pulses.vel_ned, wire.shift_ns)"
        )
    return TrueMotion(
        np.asarray(pulses["t_ns"], dtype=np.int64) + int(wire["shift_ns"]),
        np.asarray(pulses["vel_ned"], dtype=np.float64),
    )


def read_true_terrain(path: Path) -> TrueTerrain:
    """The true DEM and reference point track of a simulated array run.

    Parameters
    ----------
    path : Path
        The run's ``truth.json`` (``dem``: ``height_m``, ``spacing_m``, ``origin_ne_m``;
        ``pulses``: ``t_ns``, ``pos_ned``; ``scenario``: ``scene_north_m``,
        ``scene_half_width_m``; ``wire.shift_ns`` if any, added to the pulse times).

    Raises
    ------
    DataFileError
        Naming the file and the key when it cannot be read or lacks the array run's parts.
    """
    try:
        truth: Any = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise DataFileError(f"--truth {path}: cannot read as JSON: {exc}") from exc
    for key, sub in (
        ("dem", "height_m"),
        ("dem", "spacing_m"),
        ("dem", "origin_ne_m"),
        ("pulses", "t_ns"),
        ("pulses", "pos_ned"),
        ("scenario", "scene_north_m"),
        ("scenario", "scene_half_width_m"),
    ):
        if not isinstance(truth, dict) or sub not in truth.get(key, {}):
            raise DataFileError(f"--truth {path}: no {key}.{sub} (not an array run's truth?)")
    dem, scn, pulses = truth["dem"], truth["scenario"], truth["pulses"]
    n0, e0 = (float(v) for v in dem["origin_ne_m"])
    lo, hi = (float(v) for v in scn["scene_north_m"])
    return TrueTerrain(
        height_m=np.asarray(dem["height_m"], dtype=np.float64),
        spacing_m=float(dem["spacing_m"]),
        origin_ne_m=(n0, e0),
        scene_north_m=(lo, hi),
        scene_half_width_m=float(scn["scene_half_width_m"]),
        t_ns=np.asarray(pulses["t_ns"], dtype=np.int64) + _shift_ns(truth),
        pos_ned=np.asarray(pulses["pos_ned"], dtype=np.float64),
        source=f"--truth {path}",
    )


def _shift_ns(truth: dict[str, Any]) -> int:
    """``wire.shift_ns`` of a truth record (0 without one), ns."""
    wire = truth.get("wire")
    shift = wire.get("shift_ns", 0) if isinstance(wire, dict) else 0
    return int(shift) if isinstance(shift, int) else 0
