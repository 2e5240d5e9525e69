"""``sarmoco report STORE``: quicklook PNGs and a metrics summary of a recorded run.

Writes into the output folder:

- ``image.png``: the image strip (tiles side by side along track) in dB, metre axes,
  scale bar;
- ``motion.png``: the INS motion solution per pulse (d_los, phase, range shift);
- ``autofocus.png``: autofocus estimates per subaperture (a_y, a_z, κ0), when recorded;
- ``compare.png``: a window around the brightest target focused three ways, side by side
  on one dB scale: raw (the recorded raw echoes backprojected along the straight
  reference track), INS only (the same echoes backprojected along the track the INS
  velocities give) and INS + autofocus (the recorded tile); ``cuts.png``: azimuth and
  range cuts of the three through the target against the ideal sinc;
- ``index.html``: the pictures and the tables of ``report.txt`` in one page;
- ``report.json`` and ``report.txt``: run totals, per-tile entropy and contrast, and the
  point-target measures (PSLR, ISLR, IRW) of the brightest isolated scatterers (corner
  reflectors, or the simulator's targets).
"""

from __future__ import annotations

import dataclasses
import html
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sarmoco.daemon.config import Config, parse_config
from sarmoco.drivers.samples import to_complex64
from sarmoco.errors import ProcessingError, RecorderError
from sarmoco.processing import rangecomp
from sarmoco.processing.geometry import ReferenceTrack, look_angle, vector_to_imaging
from sarmoco.processing.imaging.backprojection import (
    DEFAULT_UPSAMPLE,
    RangeLines,
    backproject_into,
)
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.metrics import (
    image_contrast,
    image_entropy,
    point_target_metrics,
    upsample_cut,
)
from sarmoco.processing.mocomp import LosState, integrate_los
from sarmoco.processing.types import Image
from sarmoco.products.georeference import beam_squint_rad
from sarmoco.products.geotiff import write_geotiffs
from sarmoco.products.quicklook import (
    plot_cuts,
    plot_image,
    plot_overlays,
    plot_panels,
    plot_series,
)
from sarmoco.store.reader import RunStore, open_store

BRIGHT_POINTS = 5
"""How many of the brightest scatterers are measured."""

POINT_SEPARATION_M = 5.0
"""Minimum distance between two measured scatterers, m."""

COMPARE_HALF_M = 4.0
"""Half size of the window re-focused around the brightest target for the comparison, m."""

COMPARE_OVERSAMPLING = 1.5
"""The comparison keeps every k-th pulse, k the largest that leaves the pulse rate at least
this many times the Doppler bandwidth of the processed beam."""

PANELS = ("raw (no motion compensation)", "INS only", "INS + autofocus")
"""Titles of the comparison panels, in order."""

POINT_CONTRAST_DB = 20.0
"""A scatterer is measured only if its peak stands this far above the image's median
magnitude (noise and clutter peaks, whose PSLR means nothing, stand ~10 dB above it), dB."""


def strip(store: RunStore) -> Image | None:
    """The recorded tiles joined along track (axis 0); None without tiles.

    Tiles of one reference-track segment are in that track's frame; segments follow each
    other in time, each shifted along axis 0 to start where the one before ended (so the
    first segment keeps its own coordinates, and a single-segment run is unchanged).
    """
    segments: dict[int, list[Image]] = {}
    for _, image, attrs in store.images():
        segments.setdefault(int(attrs.get("reference_track", {}).get("t0_ns", 0)), []).append(image)
    if not segments:
        return None
    parts: list[tuple[Image, float]] = []
    end = -np.inf
    for t0 in sorted(segments):
        tiles = sorted(segments[t0], key=lambda im: float(im.axis0_m[0]))
        first = float(tiles[0].axis0_m[0])
        shift = 0.0 if not parts else end - first + abs(float(np.diff(tiles[0].axis0_m[:2])[0]))
        parts += [(t, shift) for t in tiles]
        end = float(tiles[-1].axis0_m[-1]) + shift
    return Image(
        np.concatenate([t.data for t, _ in parts], axis=0),
        np.concatenate([t.axis0_m + s for t, s in parts]),
        parts[0][0].axis1_m,
        parts[0][0].frame,
    )


def bright_points(image: Image, n: int = BRIGHT_POINTS) -> list[dict[str, float]]:
    """Point-target measures of the ``n`` brightest isolated scatterers.

    A candidate pixel is measured only if it is the maximum of the window of
    ``POINT_SEPARATION_M`` around it (a sidelobe of a brighter neighbour is not), stands
    ``POINT_CONTRAST_DB`` above the image's median magnitude, and is at least
    ``POINT_SEPARATION_M`` from a scatterer already measured.
    """
    mag = np.abs(image.data)
    dx, dy = image.spacing_m
    half0, half1 = round(POINT_SEPARATION_M / abs(dx)), round(POINT_SEPARATION_M / abs(dy))
    floor = float(np.median(mag)) * 10 ** (POINT_CONTRAST_DB / 20)
    found: list[dict[str, float]] = []
    order = np.argsort(mag, axis=None)[::-1]
    taken: list[tuple[float, float]] = []
    for flat in order[: 200 * n]:
        i, j = (int(k) for k in np.unravel_index(int(flat), mag.shape))
        if mag[i, j] < floor:
            break
        x, y = float(image.axis0_m[i]), float(image.axis1_m[j])
        if any(np.hypot(x - a, y - b) < POINT_SEPARATION_M for a, b in taken):
            continue
        rows = slice(max(i - half0, 0), i + half0 + 1)
        cols = slice(max(j - half1, 0), j + half1 + 1)
        if mag[rows, cols].max() > mag[i, j]:
            continue
        taken.append((x, y))
        sub = Image(image.data[rows, cols], image.axis0_m[rows], image.axis1_m[cols], image.frame)
        try:
            m = point_target_metrics(sub, through_peak=True)
        except ProcessingError:
            continue
        found.append(
            {
                "x_m": m.axis0.peak_m,
                "y_m": m.axis1.peak_m,
                "peak_db": float(20 * np.log10(mag[i, j] / mag.max())),
                "pslr_az_db": m.axis0.pslr_db,
                "islr_az_db": m.axis0.islr_db,
                "irw_az_m": m.axis0.irw_m,
                "pslr_rg_db": m.axis1.pslr_db,
                "islr_rg_db": m.axis1.islr_db,
                "irw_rg_m": m.axis1.irw_m,
            }
        )
        if len(found) == n:
            break
    return found


def _track(attrs: dict[str, Any]) -> ReferenceTrack:
    """The reference track of a tile's ``reference_track`` attribute."""
    return ReferenceTrack(
        origin_ned=np.asarray(attrs["origin_ned"], dtype=np.float64),
        x_hat=np.asarray(attrs["x_hat_ned"], dtype=np.float64),
        y_hat=np.asarray(attrs["y_hat_ned"], dtype=np.float64),
        v0_mps=float(attrs["v0_mps"]),
        t0_ns=int(attrs["t0_ns"]),
    )


def _segment_strip(
    store: RunStore, track: Mapping[str, Any], tile: Image, x_lo: float, x_hi: float
) -> Image:
    """``tile`` joined along track with the tiles of the same reference track (and width)
    that hold pixels between ``x_lo`` and ``x_hi`` (m), so a window reaching past the tile's
    edges is whole."""
    parts = [tile]
    for _, other, attrs in store.images():
        if attrs.get("reference_track") != track or other.data.shape[1] != tile.data.shape[1]:
            continue
        if other.axis0_m[0] == tile.axis0_m[0]:
            continue  # the tile itself
        if float(other.axis0_m[-1]) >= x_lo and float(other.axis0_m[0]) <= x_hi:
            parts.append(other)
    parts.sort(key=lambda im: float(im.axis0_m[0]))
    return Image(
        np.concatenate([p.data for p in parts], axis=0),
        np.concatenate([p.axis0_m for p in parts]),
        tile.axis1_m,
        tile.frame,
    )


def _brightest_window(store: RunStore, half_m: tuple[float, float]) -> tuple[Image, ReferenceTrack]:
    """The window of ``half_m`` (along track, ground range; m) around the brightest pixel of
    all tiles, and its track.

    Raises
    ------
    RecorderError
        The store has no tiles, or its tiles carry no reference track.
    """
    best: tuple[float, int] | None = None
    for k, image, _ in store.images():
        peak = float(np.abs(image.data).max())
        if best is None or peak > best[0]:
            best = (peak, k)
    if best is None:
        raise RecorderError(f"{store.path}: no image tiles to compare")
    tile, attrs = store.image(best[1])
    if "reference_track" not in attrs:
        raise RecorderError(f"{store.path}: tile {best[1]} has no reference_track attribute")
    x_peak = float(tile.axis0_m[int(np.argmax(np.abs(tile.data)) // tile.data.shape[1])])
    tile = _segment_strip(
        store, attrs["reference_track"], tile, x_peak - half_m[0], x_peak + half_m[0]
    )
    i, j = np.unravel_index(int(np.argmax(np.abs(tile.data))), tile.data.shape)
    h0 = round(half_m[0] / abs(tile.spacing_m[0]))
    h1 = round(half_m[1] / abs(tile.spacing_m[1]))
    rows = slice(max(int(i) - h0, 0), int(i) + h0 + 1)
    cols = slice(max(int(j) - h1, 0), int(j) + h1 + 1)
    window = Image(tile.data[rows, cols], tile.axis0_m[rows], tile.axis1_m[cols], tile.frame)
    return window, _track(attrs["reference_track"])


def focus_comparison(
    store: RunStore, half_m: tuple[float, float] = (COMPARE_HALF_M, COMPARE_HALF_M)
) -> tuple[dict[str, Image], int]:
    """The brightest target's window focused three ways (:data:`PANELS`), on one grid.

    Raw: the recorded raw echoes, range-compressed and backprojected with the antenna on
    the straight reference track (``ReferenceTrack.position_imaging``). INS only: the same
    echoes backprojected with the antenna where the recorded INS velocities (motion table,
    NED m/s, integrated by the trapezoid rule in the imaging frame from the segment's
    first pulse, as the daemon's LOS compensation does for ΔY, ΔZ) put it. INS + autofocus:
    the recorded tile. Only the pulses whose beam (``imaging.azimuth_beamwidth_deg`` plus
    the squint tolerance, about the squint of the segment's beam centre, :func:`beam_squint_rad`)
    covers the window are used, every k-th (``COMPARE_OVERSAMPLING``), and a pixel takes a
    pulse only within that beam, as in the daemon.
    The two re-focused windows are scaled to the recorded one's energy, so that on one dB
    scale a defocused target shows as a lower, wider peak.

    Returns
    -------
    panels : dict of str to Image
        :data:`PANELS` to the window, ground plane of the segment's imaging frame (m).
    decimation : int
        k, the pulse decimation of the re-focused windows.

    Raises
    ------
    RecorderError
        No raw echoes or no motion recorded, no tiles, or no pulse sees the window.
    """
    window, track = _brightest_window(store, half_m)
    try:
        store.read("pulses", ["echo"], 0, 0)
    except RecorderError as exc:
        raise RecorderError(f"{store.path}: no raw echoes recorded (recorder.raw_echoes)") from exc
    cfg: Config = parse_config(store.attrs["config"])
    radar = cfg.radar.params()
    motion = store.read("motion", ["pulse_id", "t_ns", "vel_ned", "d_los_m"])
    pulses = store.read("pulses", ["pulse_id"])
    # the segment: pulses from the track's start on, up to the first not compensated (turn)
    seg = np.flatnonzero(motion["t_ns"] >= track.t0_ns)
    bad = seg[~np.isfinite(motion["d_los_m"][seg])]
    seg = seg[: int(np.searchsorted(seg, bad[0])) if bad.size else seg.size]
    if seg.size < 2:
        raise RecorderError(f"{store.path}: no compensated pulses in the target's segment")
    t_ns = motion["t_ns"][seg]
    vel = vector_to_imaging(motion["vel_ned"][seg], track)
    disp, _ = integrate_los(t_ns, vel, LosState(last_vel_yz=np.zeros(3), disp_yz_m=np.zeros(3)))
    nominal = track.position_imaging(t_ns)
    ins = nominal[0] + disp
    # pulses whose beam sees the window, every k-th
    beam = cfg.imaging.imaged_beam_rad()
    y_c = float(np.mean(window.axis1_m))
    rho = math.hypot(y_c, cfg.geometry.height_m)
    centre = beam_squint_rad(store, track, cfg, math.atan2(y_c, cfg.geometry.height_m))
    squint = (centre - beam / 2.0, centre + beam / 2.0)
    x_lo, x_hi = float(window.axis0_m[0]), float(window.axis0_m[-1])
    near = np.flatnonzero(
        (nominal[:, 0] >= x_lo - rho * math.tan(squint[1]))
        & (nominal[:, 0] <= x_hi - rho * math.tan(squint[0]))
    )
    if near.size < 4:
        raise RecorderError(f"{store.path}: no recorded pulse sees the brightest target")
    doppler_hz = 4.0 * track.v0_mps * math.sin(beam / 2.0) / radar.wavelength_m
    k = max(1, int(radar.prf_hz / (COMPARE_OVERSAMPLING * doppler_hz)))
    near = near[::k]
    rows = np.searchsorted(pulses["pulse_id"], motion["pulse_id"][seg][near])
    a, b = int(rows.min()), int(rows.max()) + 1
    got = store.read("pulses", ["pulse_id", "echo"], a, b)  # damaged chunks left out
    have = np.isin(motion["pulse_id"][seg][near], got["pulse_id"])
    near = near[have]
    echo = to_complex64(
        got["echo"][np.searchsorted(got["pulse_id"], motion["pulse_id"][seg][near])]
    )
    window_type = None if cfg.imaging.window == "none" else cfg.imaging.window
    rc = rangecomp.compress(radar, echo, window_type)
    grid = PlaneGrid(window.axis0_m, window.axis1_m, (0.0, 0.0, cfg.geometry.height_m))
    range_m = rangecomp.range_axis_m(radar)
    energy = float(np.sum(np.abs(window.data) ** 2))
    panels: dict[str, Image] = {}
    lines = RangeLines.upsample(rc, range_m, DEFAULT_UPSAMPLE)
    for name, apc in zip(PANELS[:2], (nominal[near], ins[near]), strict=True):
        data = np.zeros((window.axis0_m.size, window.axis1_m.size), dtype=np.complex64)
        backproject_into(
            data, lines, apc, radar.wavelength_m, grid,
            beam_squint_rad=np.tile(squint, (apc.shape[0], 1)),
        )  # fmt: skip
        scale = math.sqrt(energy / max(float(np.sum(np.abs(data) ** 2)), 1e-30))
        panels[name] = Image(data * scale, window.axis0_m, window.axis1_m, window.frame)
    panels[PANELS[2]] = window
    return panels, k


def _ideal_resolution_m(cfg: Config, slant_m: float, ground_m: float) -> tuple[float, float]:
    """Azimuth λ / (4 sin(θ/2)) of the antenna beam θ and ground-range c / (2 B) · R / y, m.

    ``slant_m``, ``ground_m``: the target's slant and ground range, m.
    """
    radar = cfg.radar.params()
    beam = math.radians(cfg.imaging.azimuth_beamwidth_deg)
    azimuth = radar.wavelength_m / (4.0 * math.sin(beam / 2.0))
    return azimuth, radar.range_resolution_m * slant_m / ground_m


def write_comparison(
    store: RunStore, out_dir: Path, half_m: tuple[float, float] = (COMPARE_HALF_M, COMPARE_HALF_M)
) -> ComparisonSummary:
    """Write ``compare.png`` and ``cuts.png``; the panels' point-target measures.

    ``half_m``: half size of the window around the brightest target, along track and in
    ground range, m (an extended scene's whole patch, or a point target's neighbourhood).
    """
    panels, k = focus_comparison(store, half_m)
    ref = next(iter(panels.values()))
    title = "brightest target, the same echoes focused 3 ways"
    data = {n: im.data for n, im in panels.items()}
    plot_panels(data, ref.axis0_m, ref.axis1_m, out_dir / "compare.png", title)
    cfg = parse_config(store.attrs["config"])
    top = max(float(np.abs(im.data).max()) for im in panels.values())
    stats: dict[str, dict[str, float | None]] = {}
    up = 8
    cuts: dict[str, dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.generic]]]] = {
        "azimuth x (m)": {},
        "ground range y (m)": {},
    }
    for name, im in panels.items():
        i, j = np.unravel_index(int(np.argmax(np.abs(im.data))), im.data.shape)
        entry: dict[str, float | None] = {
            "peak_db": float(20 * np.log10(np.abs(im.data).max() / top))
        }
        try:
            m = point_target_metrics(im, through_peak=True)
            entry.update(pslr_az_db=m.axis0.pslr_db, irw_az_m=m.axis0.irw_m,
                         pslr_rg_db=m.axis1.pslr_db, irw_rg_m=m.axis1.irw_m)  # fmt: skip
        except ProcessingError:
            entry.update(pslr_az_db=None, irw_az_m=None, pslr_rg_db=None, irw_rg_m=None)
        stats[name] = entry
        for direction, axis, cut in (
            ("azimuth x (m)", im.axis0_m, im.data[:, j]),
            ("ground range y (m)", im.axis1_m, im.data[i, :]),
        ):
            fine = axis[0] + np.arange(axis.size * up) * (axis[1] - axis[0]) / up
            cuts[direction][name] = (fine, upsample_cut(cut, up) * np.abs(cut).max() / top)
    af = panels[PANELS[2]]
    i, j = np.unravel_index(int(np.argmax(np.abs(af.data))), af.data.shape)
    x0, y0 = float(af.axis0_m[i]), float(af.axis1_m[j])
    res_az, res_rg = _ideal_resolution_m(cfg, math.hypot(y0, cfg.geometry.height_m), y0)
    ideal = {}
    for (direction, curves), centre, res in zip(
        cuts.items(), (x0, y0), (res_az, res_rg), strict=True
    ):
        x = curves[PANELS[2]][0]
        ideal[direction] = (x, np.abs(np.sinc((x - centre) / res)))
    plot_cuts(cuts, ideal, out_dir / "cuts.png",
              f"cuts through the brightest target (ideal sinc: {res_az:.3f} m azimuth, "
              f"{res_rg:.3f} m ground range resolution)")  # fmt: skip
    return ComparisonSummary(k, (res_az, res_rg), stats)


def _smooth(values: npt.NDArray[np.float64], n: int) -> npt.NDArray[np.float64]:
    """Moving average of ``n`` samples (same length; the ends average what they have)."""
    kernel = np.ones(max(n, 1))
    num = np.convolve(values, kernel, mode="same")
    return np.asarray(num / np.convolve(np.ones_like(values), kernel, mode="same"))


def _detrend(t: npt.NDArray[np.float64], v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``v`` less its least-squares line over ``t`` (what no Doppler rate can see)."""
    return np.asarray(v - np.polyval(np.polyfit(t, v, 1), t))


def _los_acceleration(
    t_s: npt.NDArray[np.float64], d_los_m: npt.NDArray[np.float64], window_s: float
) -> npt.NDArray[np.float64]:
    """Second derivative of a LOS displacement (m/s²), averaged over ``window_s`` as a
    subaperture's Doppler rate averages it."""
    acc = np.gradient(np.gradient(d_los_m, t_s), t_s)
    return _smooth(acc, round(window_s / float(np.median(np.diff(t_s)))))


@dataclass(frozen=True)
class TrueMotion:
    """The antenna phase centre's true motion (a simulated run's), to score the INS's
    motion solution and the autofocus's residual against.

    Attributes
    ----------
    t_ns : ndarray of int64, shape (N,)
        Times of the samples on the store's GPS time base, ns, increasing.
    vel_ned : ndarray of float64, shape (N, 3)
        True APC velocity, NED, m/s.
    """

    t_ns: npt.NDArray[np.int64]
    vel_ned: npt.NDArray[np.float64]


def motion_comparison(
    store: RunStore, truth: TrueMotion | None = None
) -> tuple[dict[str, dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]],
           dict[str, float]]:  # fmt: skip
    """The INS's LOS motion beside the autofocus's residual estimate (and the truth's).

    The autofocus estimates the LOS acceleration left after the INS compensation,
    ``a_los = a_y sin β_c + a_z cos β_c`` at the scene centre's look angle β_c (docs/
    methods.md §3; positive toward the scene, as ``d_los``), one per subaperture; its
    double integral (trapezoid over the subaperture centres) is the residual displacement
    it found, shown less its best line (a Doppler rate sees neither offset nor drift).
    With the true motion the true LOS displacement is integrated as the daemon integrates
    the INS's, and the residual the autofocus should find is true − INS.
    Times: s from the first compensated pulse; the autofocus's time axis starts at the
    first pulse it was given, the same pulse for a run of one segment.

    Returns
    -------
    panels : dict
        Panel label to curve name to (t s, values), for :func:`plot_overlays`.
    stats : dict
        ``ins_d_los_rms_m``; with autofocus estimates ``autofocus_residual_rms_m``; with the
        truth also ``true_residual_rms_m`` and ``autofocus_error_rms_m`` (autofocus − true
        residual, both detrended, over the subaperture centres), m.

    Raises
    ------
    RecorderError
        No compensated pulse recorded.
    """
    cfg = parse_config(store.attrs["config"])
    motion = store.read("motion", ["t_ns", "d_los_m"])
    rows = np.flatnonzero(np.isfinite(motion["d_los_m"]))
    if rows.size < 3:
        raise RecorderError(f"{store.path}: no compensated pulses to plot the motion of")
    t0 = int(motion["t_ns"][rows[0]])
    t = (motion["t_ns"][rows] - t0) * 1e-9
    ins = motion["d_los_m"][rows]
    beta = float(look_angle(cfg.geometry.center_slant_range_m, cfg.geometry.height_m))
    window = cfg.autofocus.subaperture_s
    disp: dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = {
        "INS d_los": (t, ins)
    }
    resid: dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = {}
    accel: dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = {
        "INS d_los''": (t, _los_acceleration(t, ins, window))
    }
    stats = {"ins_d_los_rms_m": float(np.sqrt(np.mean(ins**2)))}
    true_resid = None
    if truth is not None:
        tt = truth.t_ns
        track = _track(store.attrs["reference_track"])
        vel = vector_to_imaging(truth.vel_ned, track)
        keep = tt >= t0
        yz, _ = integrate_los(tt[keep], vel[keep][:, 1:], LosState())
        true_los = np.interp(t, (tt[keep] - t0) * 1e-9,
                             yz[:, 0] * math.sin(beta) + yz[:, 1] * math.cos(beta))  # fmt: skip
        true_resid = true_los - ins
        disp["true d_los"] = (t, true_los)
        resid["true residual (true - INS)"] = (t, _detrend(t, true_resid) * 1e3)
        accel["true residual''"] = (t, _los_acceleration(t, true_resid, window))
        stats["true_residual_rms_m"] = float(np.std(_detrend(t, true_resid)))
    if "autofocus" in store.tables() and store.committed("autofocus") >= 3:
        a = store.read("autofocus", ["t_center_s", "a_y_mps2", "a_z_mps2"])
        ok = np.isfinite(a["a_y_mps2"]) & np.isfinite(a["a_z_mps2"])
        ta = a["t_center_s"][ok]
        a_los = a["a_y_mps2"][ok] * math.sin(beta) + a["a_z_mps2"][ok] * math.cos(beta)
        if ta.size >= 3:
            vel_af = np.concatenate(
                [[0.0], np.cumsum(0.5 * (a_los[1:] + a_los[:-1]) * np.diff(ta))]
            )
            d_af = np.concatenate(
                [[0.0], np.cumsum(0.5 * (vel_af[1:] + vel_af[:-1]) * np.diff(ta))]
            )
            d_af = _detrend(ta, d_af)
            accel["autofocus a_los"] = (ta, a_los)
            resid["autofocus residual"] = (ta, d_af * 1e3)
            stats["autofocus_residual_rms_m"] = float(np.std(d_af))
            if true_resid is not None:
                inside = (ta >= t[0]) & (ta <= t[-1])
                truth_at = _detrend(ta[inside], np.interp(ta[inside], t, true_resid))
                err = _detrend(ta[inside], d_af[inside]) - truth_at
                stats["autofocus_error_rms_m"] = float(np.sqrt(np.mean(err**2)))
    panels = {"LOS displacement (m)": disp, "LOS acceleration (m/s²)": accel}
    if resid:
        panels = {"LOS displacement (m)": disp,
                  "residual LOS displacement, detrended (mm)": resid,
                  "LOS acceleration (m/s²)": accel}  # fmt: skip
    return panels, stats


@dataclass(frozen=True)
class ImageSummary:
    """The focused strip of a run, as the report measures it.

    Attributes
    ----------
    shape : tuple of int
        Pixels along track and in ground range.
    pixel_m : tuple of float
        Pixel spacing along track and in ground range, m.
    entropy : float
        Image entropy (:func:`~sarmoco.processing.metrics.image_entropy`).
    contrast : float
        Image contrast (:func:`~sarmoco.processing.metrics.image_contrast`).
    points : list of dict
        The brightest isolated scatterers' measures (:func:`bright_points`), brightest first.
    """

    shape: tuple[int, int]
    pixel_m: tuple[float, float]
    entropy: float
    contrast: float
    points: list[dict[str, float]]


@dataclass(frozen=True)
class MotionSummary:
    """The INS motion solution's line-of-sight displacement over the run.

    Attributes
    ----------
    d_los_rms_m : float
        RMS of the per-pulse LOS displacement (pulses with a solution), m.
    d_los_peak_to_peak_m : float
        Its peak-to-peak excursion, m.
    """

    d_los_rms_m: float
    d_los_peak_to_peak_m: float


@dataclass(frozen=True)
class AutofocusSummary:
    """The autofocus table of a run.

    Attributes
    ----------
    subapertures : int
        How many subaperture estimates the store holds.
    """

    subapertures: int


@dataclass(frozen=True)
class ComparisonSummary:
    """The brightest target focused three ways (:func:`write_comparison`).

    Attributes
    ----------
    decimation : int
        The comparison keeps every ``decimation``-th pulse.
    ideal_resolution_m : tuple of float
        Ideal resolution along track and in ground range at the target, m.
    panels : dict
        Per panel title (:data:`PANELS`): ``peak_db`` (re the brightest panel's),
        ``pslr_az_db``, ``irw_az_m``, ``pslr_rg_db``, ``irw_rg_m``; a measure the panel's
        response does not allow (no -3 dB point or no sidelobe inside the window) is None.
    """

    decimation: int
    ideal_resolution_m: tuple[float, float]
    panels: dict[str, dict[str, float | None]]


@dataclass(frozen=True)
class ReportSummary:
    """The summary of a recorded run (``report.json``, :meth:`as_dict`).

    A part the store does not allow is None, and the reason, where one is known, is in the
    matching ``*_skipped`` attribute.

    Attributes
    ----------
    store : str
        The store's path.
    complete : bool
        Whether the run closed its store.
    run : dict
        The run's metrics, as the store records them.
    versions : dict
        The software versions the store records.
    pulses_committed : int
        Pulses recorded.
    image : ImageSummary or None
        The focused strip, when the store holds image tiles.
    geotiff : list of str or None
        The GeoTIFF files written (one per reference-track segment).
    geotiff_skipped : str or None
        Why no GeoTIFF was written.
    motion : MotionSummary or None
        The INS motion solution, when some pulse has one.
    autofocus : AutofocusSummary or None
        The autofocus table, when recorded.
    motion_estimates : dict or None
        RMS figures of :func:`motion_comparison`, m.
    motion_estimates_skipped : str or None
        Why they were not drawn.
    comparison : ComparisonSummary or None
        The brightest target focused three ways.
    comparison_skipped : str or None
        Why it was not drawn.
    damaged_chunks_skipped : dict or None
        Damaged chunks read around: rows or tiles per chunk path.
    """

    store: str
    complete: bool
    run: dict[str, Any]
    versions: dict[str, Any]
    pulses_committed: int
    image: ImageSummary | None = None
    geotiff: list[str] | None = None
    geotiff_skipped: str | None = None
    motion: MotionSummary | None = None
    autofocus: AutofocusSummary | None = None
    motion_estimates: dict[str, float] | None = None
    motion_estimates_skipped: str | None = None
    comparison: ComparisonSummary | None = None
    comparison_skipped: str | None = None
    damaged_chunks_skipped: dict[str, int] | None = None

    def as_dict(self) -> dict[str, Any]:
        """The JSON document: every attribute that is not None, under its own name."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


def write_report(
    store_path: Path,
    out_dir: Path,
    compare_half_m: tuple[float, float] = (COMPARE_HALF_M, COMPARE_HALF_M),
    truth: TrueMotion | None = None,
) -> ReportSummary:
    """Write the quicklooks and the summary of a store; returns the summary.

    ``compare_half_m``: half size of the comparison window (:func:`write_comparison`), m.
    ``truth``: the run's true motion, drawn in ``motion_estimates.png`` and scored
    (:func:`motion_comparison`).

    Raises
    ------
    RecorderError
        If the store cannot be opened or holds no pulses.
    """
    store = open_store(store_path, skip_damaged=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    attrs = store.attrs
    if store.committed("pulses") == 0:
        raise RecorderError(f"{store_path}: no committed pulses")
    image = strip(store)
    parts: dict[str, Any] = {}
    if image is not None:
        parts.update(_image_part(image, store, store_path, out_dir))
    if store.committed("motion"):
        parts.update(_motion_part(store, truth, out_dir))
    if "autofocus" in store.tables() and store.committed("autofocus"):
        a = store.read("autofocus", ["t_center_s", "a_y_mps2", "a_z_mps2", "kappa"])
        plot_series(a["t_center_s"], {"a_y (m/s²)": a["a_y_mps2"], "a_z (m/s²)": a["a_z_mps2"],
                                       "κ0 (Hz/s)": a["kappa"][:, 0]},
                    out_dir / "autofocus.png", "autofocus estimates per subaperture")  # fmt: skip
        parts["autofocus"] = AutofocusSummary(int(a["t_center_s"].shape[0]))
    if image is not None and store.committed("motion") and _has_echoes(store):
        try:
            parts["comparison"] = write_comparison(store, out_dir, compare_half_m)
        except RecorderError as exc:  # e.g. the brightest target's pulses were not kept
            parts["comparison_skipped"] = str(exc)
    summary = ReportSummary(
        store=str(store_path),
        complete=bool(attrs.get("complete", False)),
        run=attrs.get("metrics", {}),
        versions=attrs.get("versions", {}),
        pulses_committed=store.committed("pulses"),
        damaged_chunks_skipped=dict(store.skipped) if store.skipped else None,
        **parts,
    )
    (out_dir / "report.json").write_text(json.dumps(summary.as_dict(), indent=2, default=float))
    text = _text(summary)
    (out_dir / "report.txt").write_text(text)
    (out_dir / "index.html").write_text(_html(summary, text, out_dir))
    return summary


def _image_part(image: Image, store: RunStore, store_path: Path, out_dir: Path) -> dict[str, Any]:
    """``image.png`` and the GeoTIFFs; the summary's ``image`` and ``geotiff*`` attributes."""
    plot_image(image.data, image.axis0_m, image.axis1_m, out_dir / "image.png",
               f"{store_path.name}: backprojection, ground plane",
               ("along-track x (m)", "ground range y (m)"))  # fmt: skip
    rows, cols = image.data.shape
    part: dict[str, Any] = {
        "image": ImageSummary(
            shape=(rows, cols),
            pixel_m=image.spacing_m,
            entropy=image_entropy(image.data),
            contrast=image_contrast(image.data),
            points=bright_points(image),
        )
    }
    try:  # the georeferenced quicklook, one GeoTIFF per reference-track segment
        part["geotiff"] = [g.path.name for g in write_geotiffs(store, out_dir)]
    except RecorderError as exc:  # no absolute position, or not a ground-plane image
        part["geotiff_skipped"] = str(exc)
    return part


def _motion_part(store: RunStore, truth: TrueMotion | None, out_dir: Path) -> dict[str, Any]:
    """``motion.png`` and ``motion_estimates.png``; the summary's ``motion`` and
    ``motion_estimates*`` attributes."""
    m = store.read("motion", ["t_ns", "d_los_m", "phase_rad", "range_shift_m"])
    t = (m["t_ns"] - m["t_ns"][0]) * 1e-9
    plot_series(t, {"d_los (m)": m["d_los_m"], "phase (rad)": m["phase_rad"],
                    "range shift (m)": m["range_shift_m"]},
                out_dir / "motion.png", "INS motion solution per pulse")  # fmt: skip
    part: dict[str, Any] = {}
    d_los = m["d_los_m"][np.isfinite(m["d_los_m"])]  # turns, no navigation: no solution
    if d_los.size:
        part["motion"] = MotionSummary(
            d_los_rms_m=float(np.sqrt(np.mean(d_los**2))),
            d_los_peak_to_peak_m=float(np.ptp(d_los)),
        )
    try:
        panels, part["motion_estimates"] = motion_comparison(store, truth)
        plot_overlays(panels, out_dir / "motion_estimates.png",
                      "LOS motion: the INS solution and the autofocus's estimate"
                      + ("" if truth is None else " (and the truth)"))  # fmt: skip
    except RecorderError as exc:
        part["motion_estimates_skipped"] = str(exc)
    return part


def _has_echoes(store: RunStore) -> bool:
    try:
        store.read("pulses", ["echo"], 0, 0)
    except RecorderError:
        return False
    return True


PICTURES = (
    ("image.png", "Focused strip (INS + autofocus)"),
    ("compare.png", "Before and after: raw, INS only, INS + autofocus"),
    ("cuts.png", "Point-target cuts against the ideal sinc"),
    ("motion.png", "INS motion solution"),
    ("motion_estimates.png", "LOS motion: INS solution beside the autofocus's estimate"),
    ("autofocus.png", "Autofocus estimates"),
)
"""The report's pictures, in page order, with their headings."""


def _html(summary: ReportSummary, text: str, out_dir: Path) -> str:
    """``index.html``: report.txt's tables and the pictures present (relative links)."""
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>sarmoco report: {html.escape(Path(summary.store).name)}</title>",
        "<style>body{font-family:sans-serif;margin:1em 2em}img{max-width:100%}"
        "pre{background:#f4f4f4;padding:.5em}</style></head><body>",
        f"<h1>sarmoco report: {html.escape(Path(summary.store).name)}</h1>",
        f"<pre>{html.escape(text)}</pre>",
    ]
    for name, heading in PICTURES:
        if (out_dir / name).exists():
            parts.append(f'<h2>{html.escape(heading)}</h2><img src="{name}" alt="{heading}">')
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _text(summary: ReportSummary) -> str:
    run = summary.run
    state = "complete" if summary.complete else "INCOMPLETE"
    lines = [
        f"store            {summary.store} ({state})",
        f"pulses           {summary.pulses_committed} recorded, "
        f"{run.get('pulses_processed', '?')} focused, "
        f"{run.get('pulses_nav_flagged', '?')} flagged for navigation",
        f"INS samples      {run.get('nav_samples', '?')}",
    ]
    damaged = summary.damaged_chunks_skipped or {}
    if damaged:
        lines.append(f"DAMAGED          {len(damaged)} chunks skipped "
                     f"({sum(damaged.values())} rows or tiles): " + "; ".join(damaged))  # fmt: skip
    if (mo := summary.motion) is not None:
        lines.append(f"d_los            rms {mo.d_los_rms_m:.3f} m, "
                     f"peak-to-peak {mo.d_los_peak_to_peak_m:.3f} m")  # fmt: skip
    if summary.motion_estimates is not None:
        parts = [f"{k.removesuffix('_m')} {1e3 * v:.1f} mm"
                 for k, v in summary.motion_estimates.items()]  # fmt: skip
        lines.append("LOS motion (rms) " + ", ".join(parts))
    if (im := summary.image) is not None:
        lines.append(f"image            {im.shape[0]} x {im.shape[1]} px, entropy "
                     f"{im.entropy:.3f}, contrast {im.contrast:.3f}")  # fmt: skip
        lines.append("brightest points  x (m)    y (m)   PSLR az/rg (dB)   IRW az/rg (m)")
        for p in im.points:
            lines.append(
                f"                 {p['x_m']:7.2f} {p['y_m']:8.2f}   {p['pslr_az_db']:6.2f} "
                f"{p['pslr_rg_db']:6.2f}     {p['irw_az_m']:.3f} {p['irw_rg_m']:.3f}"
            )
    if summary.comparison_skipped is not None:
        lines.append(f"comparison       not drawn: {summary.comparison_skipped}")
    if (comp := summary.comparison) is not None:
        lines.append(f"comparison       brightest target (pulses 1 in {comp.decimation})")
        lines.append("                               peak (dB)  PSLR az/rg (dB)   IRW az/rg (m)")
        for name, s in comp.panels.items():
            keys = (("pslr_az_db", "6.2f"), ("pslr_rg_db", "6.2f"), ("irw_az_m", ".3f"),
                    ("irw_rg_m", ".3f"))  # fmt: skip
            cells = [_cell(s.get(k), f) for k, f in keys]
            lines.append(f"  {name:<29}{s['peak_db']:6.1f}     {cells[0]} {cells[1]}"
                         f"     {cells[2]} {cells[3]}")  # fmt: skip
    return "\n".join(lines) + "\n"


def _cell(value: float | None, fmt: str) -> str:
    return "     -" if value is None else format(value, fmt)
