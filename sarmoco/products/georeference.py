"""Where a store's images are on Earth: the run frame tied to the INS's geodetic positions.

The motion compensation works in the *run frame*: NED axes, origin at the antenna phase
centre (APC) of the first focused pulse, positions the trapezoid-integrated INS velocity of
the APC (the INS-only D_los, docs/methods.md §3). Reference tracks and image grids are in
that frame. The store also keeps the INS's geodetic positions (``nav/lla``) and the
geodetic origin of the run (the first of them, :class:`~sarmoco.store.schema.GeodeticOrigin`).
:func:`georeference` ties the two: the run frame is shifted by the mean difference between
the INS's positions (as NED about the geodetic origin) and the integrated track at the same
instants, so that

    ECEF(p) = ECEF(origin) + R_nedᵀ (p + offset)

for any run-frame point p (R_ned: north, east, down at the origin). The phase never uses
this: only the export and the quicklook do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sarmoco.daemon.config import Config, parse_config
from sarmoco.errors import RecorderError
from sarmoco.geodesy import (
    ecef_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_ned,
    ned_rotation,
)
from sarmoco.processing.geometry import ReferenceTrack, lever_arm_ned
from sarmoco.processing.mocomp import LosState, integrate_los
from sarmoco.processing.types import FloatArray, Image, IntArray
from sarmoco.store import schema
from sarmoco.store.flags import PushResult
from sarmoco.store.reader import RunStore


@dataclass(frozen=True)
class Georeference:
    """The run frame of a store on the WGS-84 ellipsoid.

    Attributes
    ----------
    origin : GeodeticOrigin
        The run's geodetic origin (lat, lon deg; altitude m, used as ellipsoid height).
    offset_ned_m : ndarray, shape (3,)
        Run-frame origin in NED about the geodetic origin, m.
    fit_rms_m : float
        RMS distance between the INS positions and the shifted integrated track, m.
    n_fixes : int
        INS positions the offset was fitted to.
    """

    origin: schema.GeodeticOrigin
    offset_ned_m: FloatArray
    fit_rms_m: float
    n_fixes: int

    @property
    def rotation(self) -> FloatArray:
        """Rows north, east, down in ECEF at the origin (``v_ecef = rotation.T @ v_ned``)."""
        return ned_rotation(self.origin.lla[0], self.origin.lla[1])

    def ecef(self, pos_run_m: FloatArray) -> FloatArray:
        """Run-frame points (..., 3), m → ECEF (..., 3), m."""
        ned = np.asarray(pos_run_m, dtype=np.float64) + self.offset_ned_m
        return np.asarray(geodetic_to_ecef(np.asarray(self.origin.lla)) + ned @ self.rotation)

    def ecef_vector(self, vec_ned: FloatArray) -> FloatArray:
        """NED vectors (..., 3) (velocities, unit axes) → the same vectors in ECEF."""
        return np.asarray(np.asarray(vec_ned, dtype=np.float64) @ self.rotation)

    def geodetic(self, pos_run_m: FloatArray) -> FloatArray:
        """Run-frame points (..., 3), m → latitude, longitude (deg), height (m)."""
        return ecef_to_geodetic(self.ecef(pos_run_m))

    def parameters(self) -> tuple[tuple[str, str], ...]:
        """The frame and origin as name-value pairs, for an export's metadata."""
        lat, lon, alt = self.origin.lla
        return (
            ("geodetic_origin", f"{lat:.9f} deg, {lon:.9f} deg, {alt:.3f} m"),
            ("geodetic_origin_source", self.origin.source),
            ("geodetic_origin_height", self.origin.height_note),
            ("run_frame_offset_ned_m", ",".join(f"{v:.4f}" for v in self.offset_ned_m)),
            ("georeference_fit_rms_m", f"{self.fit_rms_m:.4f}"),
            ("georeference_fixes", str(self.n_fixes)),
        )


def run_track(store: RunStore) -> tuple[IntArray, FloatArray, FloatArray]:
    """The integrated APC track of the focused pulses in the run frame.

    Returns
    -------
    t_ns : ndarray of int64, shape (P,)
        Pulse times from the first reference track's start, GPS ns.
    pos_m : ndarray, shape (P, 3)
        APC positions, run frame (NED, zero at the first focused pulse), m.
    quat : ndarray, shape (P, 4)
        INS attitude at the pulses (scalar first, body to NED).

    Raises
    ------
    RecorderError
        The store has no reference track or no focused pulse.
    """
    track = schema.decode_reference_track(
        schema.read_attr(store.attrs, schema.REFERENCE_TRACK_ATTR, dict, str(store.path)),
        f"{store.path}.{schema.REFERENCE_TRACK_ATTR}",
    )
    m = store.read(schema.MOTION.name, ["t_ns", "vel_ned", "quat"])
    keep = (
        (m["t_ns"] >= track.t0_ns)
        & np.isfinite(m["vel_ned"]).all(axis=1)
        & np.isfinite(m["quat"]).all(axis=1)
    )
    t, vel = m["t_ns"][keep], m["vel_ned"][keep]
    if t.size < 2:
        raise RecorderError(f"{store.path}: fewer than 2 focused pulses with motion")
    pos, _ = integrate_los(t, vel, LosState(last_vel_yz=np.zeros(3), disp_yz_m=np.zeros(3)))
    return t, pos, m["quat"][keep]


def georeference(store: RunStore) -> Georeference:
    """Tie a store's run frame to the INS's geodetic positions (see the module docstring).

    The INS positions are those of the INS: each is moved to the antenna by the lever arm
    (``ins.lever_arm_m`` of the run's configuration) turned by the attitude of the nearest
    pulse before the fit.

    Raises
    ------
    RecorderError
        The store has no absolute position (``geodetic_origin`` absent), or no INS position
        falls within the focused pulses.
    """
    origin = schema.decode_geodetic_origin(store.attrs, str(store.path))
    nav = store.read(schema.NAV.name, ["t_ns", "lla", "result"])
    ok = np.isfinite(nav["lla"]).all(axis=1) & (nav["result"] == int(PushResult.ACCEPTED))
    t_fix = nav["t_ns"][ok]
    offset, rms, n = _track_offset(store, t_fix, geodetic_to_ned(nav["lla"][ok], origin.lla))
    return Georeference(origin, offset, rms, n)


def _track_offset(
    store: RunStore, t_fix: IntArray, fixes_ned: FloatArray
) -> tuple[FloatArray, float, int]:
    """The run frame's origin in the frame of the INS's positions.

    Parameters
    ----------
    store : RunStore
        The run.
    t_fix : ndarray of int64, shape (F,)
        Times of the INS positions, GPS ns.
    fixes_ned : ndarray, shape (F, 3)
        INS positions (the INS's point), NED in their frame, m.

    Returns
    -------
    offset_ned_m : ndarray, shape (3,)
        Mean of the positions moved to the antenna (lever arm turned by the attitude of the
        nearest pulse) minus the integrated track at the same instants, m.
    fit_rms_m : float
        RMS of what the mean leaves, m.
    n_fixes : int
        Positions within the focused pulses.

    Raises
    ------
    RecorderError
        No position falls within the focused pulses.
    """
    cfg = parse_config(store.attrs["config"])
    t, pos, quat = run_track(store)
    inside = (t_fix >= t[0]) & (t_fix <= t[-1])
    if not inside.any():
        raise RecorderError(f"{store.path}: nav: no INS position within the focused pulses")
    t_fix = t_fix[inside]
    nearest = np.clip(np.searchsorted(t, t_fix), 0, t.size - 1)
    arm = lever_arm_ned(quat[nearest], np.asarray(cfg.ins.lever_arm_m, dtype=np.float64))
    fixes = fixes_ned[inside] + arm
    rel = (t - t[0]).astype(np.float64)
    track = np.stack(
        [np.interp((t_fix - t[0]).astype(np.float64), rel, pos[:, k]) for k in range(3)], axis=1
    )
    offset = (fixes - track).mean(axis=0)
    rms = float(np.sqrt(np.mean(np.sum((fixes - track - offset) ** 2, axis=1))))
    return offset, rms, int(inside.sum())


@dataclass(frozen=True)
class NedFrame:
    """The NED frame a store's images can be put in, tied to the run frame.

    Attributes
    ----------
    offset_ned_m : ndarray, shape (3,)
        Run-frame origin in this frame, m (``p_frame = p_run + offset``).
    description : str
        Which frame: its origin and where it comes from.
    stated : bool
        The INS named the origin (its EKF origin, or the origin of its local positions);
        False: a point of the daemon's choosing (the first geodetic fix, or the run frame's
        first antenna position), which no other receiver of the INS's data would share.
    """

    offset_ned_m: FloatArray
    description: str
    stated: bool


def ned_frame(store: RunStore) -> NedFrame:
    """The INS's own position frame where the store has positions, else the run frame.

    In order: NED about the geodetic origin (:func:`georeference`) where the INS gave
    geodetic positions; the INS's local NED frame where it gave local positions only
    (``nav/pos_ned``: for MAVLink LOCAL_POSITION_NED the autopilot's EKF origin); the run
    frame (origin at the antenna phase centre of the first focused pulse) otherwise.
    """
    try:
        geo = georeference(store)
    except RecorderError:
        pass
    else:
        lat, lon, alt = geo.origin.lla
        return NedFrame(
            geo.offset_ned_m,
            f"NED, m, about the geodetic origin {lat:.9f} deg, {lon:.9f} deg, {alt:.3f} m "
            f"({geo.origin.source}); INS positions fitted with {geo.fit_rms_m:.3f} m rms",
            geo.origin.stated,
        )
    nav = store.read(schema.NAV.name, ["t_ns", "pos_ned", "result"])
    ok = np.isfinite(nav["pos_ned"]).all(axis=1) & (nav["result"] == int(PushResult.ACCEPTED))
    try:
        offset, rms, _ = _track_offset(store, nav["t_ns"][ok], nav["pos_ned"][ok])
    except RecorderError:
        return NedFrame(
            np.zeros(3),
            "NED, m, run frame: origin at the antenna phase centre of the first focused pulse",
            False,
        )
    return NedFrame(
        offset,
        f"NED, m, the INS's own local frame (the origin of its positions, nav/pos_ned); INS "
        f"positions fitted with {rms:.3f} m rms",
        True,
    )


@dataclass(frozen=True)
class SegmentImage:
    """The tiles of one reference track joined along track (axis 0), in that track's frame.

    Attributes
    ----------
    image : Image
        Pixels and axes (m) as the tiles hold them.
    track : ReferenceTrack
        The segment's reference track (run frame).
    t0_ns, t1_ns : int
        First and last pulse time of the tiles, GPS ns.
    tiles : tuple of int
        Indices of the store's tiles joined, in order.
    """

    image: Image
    track: ReferenceTrack
    t0_ns: int
    t1_ns: int
    tiles: tuple[int, ...]


def segment_images(store: RunStore) -> list[SegmentImage]:
    """Every reference-track segment's tiles joined along track, in time order.

    Raises
    ------
    RecorderError
        A tile lacks its ``reference_track``, or tiles of a segment differ in width.
    """
    groups: dict[int, list[tuple[int, Image, dict[str, object]]]] = {}
    for k, image, attrs in store.images():
        where = f"{store.path}/{schema.IMAGES_GROUP}/{schema.tile_name(k)}"
        track_attr = schema.read_attr(attrs, schema.REFERENCE_TRACK_ATTR, dict, where)
        t0 = schema.read_attr(track_attr, "t0_ns", int, f"{where}.{schema.REFERENCE_TRACK_ATTR}")
        groups.setdefault(t0, []).append((k, image, attrs))
    out = []
    for t0 in sorted(groups):
        parts = sorted(groups[t0], key=lambda p: float(p[1].axis0_m[0]))
        first_k, first, attrs = parts[0]
        where = f"{store.path}/{schema.IMAGES_GROUP}/{schema.tile_name(first_k)}"
        if any(p[1].data.shape[1] != first.data.shape[1] for p in parts):
            raise RecorderError(f"{where}: tiles of one reference track differ in width")
        track = schema.decode_reference_track(
            attrs[schema.REFERENCE_TRACK_ATTR],  # type: ignore[arg-type]
            f"{where}.{schema.REFERENCE_TRACK_ATTR}",
        )
        image = Image(
            np.concatenate([p[1].data for p in parts], axis=0),
            np.concatenate([p[1].axis0_m for p in parts]),
            first.axis1_m,
            first.frame,
        )
        t0s = [schema.read_attr(p[2], "t0_ns", int, where) for p in parts]
        t1s = [schema.read_attr(p[2], "t1_ns", int, where) for p in parts]
        out.append(SegmentImage(image, track, min(t0s), max(t1s), tuple(p[0] for p in parts)))
    return out


def segment_image(store: RunStore, segment: int) -> SegmentImage:
    """One reference-track segment's image (:func:`segment_images`), by index.

    Raises
    ------
    RecorderError
        The store has no such segment (or :func:`segment_images` raised).
    """
    segments = segment_images(store)
    if not 0 <= segment < len(segments):
        raise RecorderError(f"{store.path}: segment {segment} (the store has {len(segments)})")
    return segments[segment]


def grid_points(image: Image, track: ReferenceTrack, ground_depth_m: float) -> FloatArray:
    """Run-frame positions (n0, n1, 3) of a ground-plane image's pixel centres, m.

    Parameters
    ----------
    image : Image
        Of frame ``"ground"``: axis 0 along-track x, axis 1 ground range y of ``track``'s
        imaging frame.
    track : ReferenceTrack
        The image's reference track.
    ground_depth_m : float
        Depth of the ground below the reference track (imaging-frame z), m.

    Raises
    ------
    RecorderError
        The image is not in the ground plane.
    """
    if image.frame != "ground":
        raise RecorderError(f"image frame {image.frame!r}: only 'ground' images are georeferenced")
    x, y = np.meshgrid(image.axis0_m, image.axis1_m, indexing="ij")
    pts = np.stack([x, y, np.full_like(x, ground_depth_m)], axis=-1)
    return np.asarray(track.origin_ned + pts @ track.rotation)


def beam_squint_rad(store: RunStore, track: ReferenceTrack, cfg: Config, look_rad: float) -> float:
    """Squint of a segment's beam centre at the look angle ``look_rad`` (rad, from the
    vertical), rad (positive: ahead along the track; 0 for a store without a ``doppler``
    table).

    The median over the segment's processing blocks (from ``track.t0_ns`` on) of the
    attitude's beam-centre squint (``doppler/squint_rad``, at the antenna's reference look
    angle, :meth:`~sarmoco.daemon.config.GeometryConfig.reference_look_rad`), carried to
    ``look_rad``: the ground squint of a cone about a level array axis turned by a crab
    ``c`` is ``asin(sin β tan c)`` (:mod:`sarmoco.processing.beam`), so its sine scales with
    ``sin β``.
    """
    try:
        d = store.read("doppler", ["t_ns", "squint_rad"])
    except RecorderError:
        return 0.0
    rows = d["t_ns"] >= track.t0_ns
    if not rows.any():
        rows = d["t_ns"] == d["t_ns"].max()
    squint = np.asarray(d["squint_rad"])[rows]
    squint = squint[np.isfinite(squint)]
    if squint.size == 0:
        return 0.0
    ref = cfg.geometry.reference_look_rad()
    sine = math.sin(float(np.median(squint))) * math.sin(look_rad) / math.sin(ref)
    return math.asin(max(-1.0, min(1.0, sine)))
