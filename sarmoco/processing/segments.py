"""Where a long strip is cut into straight reference-track segments, and which pulses are turns.

INS-only compensation measures the APC deviation (ΔY, ΔZ) from one straight reference
track (docs/methods.md §1-2). Over a survey flight (minutes of straight legs joined by turns)
the deviation from any single line grows without bound, so the strip is cut into
segments, each with its own straight track (from the INS velocity where it starts)
and its own D_los starting at 0:

- **Turn**: the heading of the INS velocity, averaged over the last ``window_s``
  (a synthetic aperture), changed by more than ``turn_rad`` (the daemon takes the azimuth
  beamwidth) against the same average one window earlier. A target's aperture then
  spans a heading change that sweeps the beam across its width: the pulse is flagged and
  not imaged. Averaging over an aperture keeps turbulence (cross-track velocity wander of
  a few tenths of m/s, i.e. about 1° of instantaneous ground-track heading at 17 m/s;
  up to 1.35° between consecutive 1.7 s averages in a real ArduPilot flight) from being
  taken for a turn, while a coordinated turn (about 12°/s in the real ArduPilot log)
  crosses the limit within about a second. Where the attitude is known, the body's
  heading (averaged over the same windows) must have turned by as much as well: in a turn
  the body turns with the course, while in gusts the course swings and the body holds its
  heading (the crab changes). On the independent acceptance scene with twice the
  motion and INS error at 6° of crab, the course alone swung by 2.26° (against a 1.91°
  beam) over the last aperture while the body's heading turned by 0.98°, and the last
  0.59 s, a third of the farthest target's aperture, were flagged a turn (its azimuth
  IRW 1.37 x). The test needs the
  window one earlier to be whole (the first ``2 window_s`` of a run are never a turn):
  at the start it held fewer pulses, down to the first pulse's heading alone: on
  ku-vehicle x0.1 with turbulence seed 3 the mean heading of 0-1.01 s (-16.0 mrad)
  against the first pulse's (+9.0 mrad) flagged 1.01-1.95 s (165 pulses) as a turn,
  and the targets' aperture was cut there.
- **New segment**: at the first pulse after a turn (the track is the mean velocity of
  the window, by then all straight flight), and wherever the running deviation
  ``hypot(ΔY, ΔZ)`` from the current track exceeds ``deviation_m``. A slow heading change
  (drift of the track) shows as a deviation growing like ``v0 t δψ``; it is caught by
  the same test before it reaches the beam tolerance at the ranges imaged. The track
  started there follows the mean velocity of the whole segment before it (when that is
  longer than the window): after a turn the first track's heading rests on one window
  of turbulent flight (about 0.3° off in the survey simulation), the next one on the
  whole leg so far, so a leg is rarely cut twice.
- **Overlap at a deviation cut** (``overlap_s`` > 0): a point target's aperture that
  straddles such a cut would be split between two tracks (1.8-2 x the azimuth IRW on the
  10-min survey). The segment started there begins ``overlap_s`` (half an aperture: the
  imaged beam's half footprint at far range over v0) *before* the cut, at the first pulse
  of the current segment no earlier than that: its track is the line through the APC at
  the cut (D_los 0 there, as at any start; the deviation test runs from there), its
  origin moved back along it to that first pulse. :attr:`SegmentPlan.cut_x_m` says where
  along it the cut lies, :attr:`SegmentPlan.offset_m` where the APC at its first pulse is
  off the line (the compensation starts from that, not from 0). The daemon
  (:mod:`sarmoco.daemon.focuser`) feeds it the pulses it kept since, lets the old segment
  run on ``overlap_s`` past the cut, and each images only its side of the cut line, so
  every target lies in one segment that holds its whole aperture. Not after a turn or a
  navigation gap: no usable pulses precede those starts.
- **After a navigation gap**: pulses without navigation (``known`` false: the daemon
  gives them placeholder velocities, held or interpolated across the hole) never start
  a segment and never enter a track's velocity. Where the known pulses are more than
  ``window_s`` apart, a segment starts at the first known pulse after the gap, its track
  along the mean velocity of the known pulses of the next ``window_s`` that the block
  holds: the flight before the gap, or the placeholders, may head elsewhere. A pixel
  takes the pulses within half the beam plus the squint tolerance of the track's
  broadside, so a track off the beam's heading cuts the aperture: after a 10 s INS
  silence on ku-vehicle x0.03 the segment started inside the silence along the held
  placeholder velocity, -14.2 mrad against the simulator's beam at 0, and the targets
  after it focused at 1.2 x the azimuth IRW (9 of the 50 mrad aperture cut).
- **Across a skip**: pulses the caller left out on purpose (``after_skip``: a live
  focuser that fell behind skipped recorded pulses with navigation) do not end the
  segment, however long the hole: the flight went on along the same track, the D_los
  integrates through the hole from the velocities each side (as across placeholders),
  and the turn and deviation tests still cut where the flight after it asks for.
  Starting over there would cost the focuser the ends and starts of segments exactly
  when it is short of time.

Everything here is a function of pulse times (GPS ns) and APC velocities (NED, m/s);
the :class:`Segmenter` carries the state from one block to the next, so feeding a strip
block by block gives the same plan as one call.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.geometry import (
    LookSide,
    ReferenceTrack,
    ned_to_imaging,
    vector_to_imaging,
)
from sarmoco.processing.mocomp import LosState, integrate_los
from sarmoco.processing.types import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class SegmentLimits:
    """When a new reference track starts and which pulses are turns.

    Parameters
    ----------
    deviation_m : float
        A new segment starts where |(ΔY, ΔZ)| from the current track exceeds this, m.
    turn_rad : float
        Change of the window-averaged heading over one window above which a pulse is in
        a turn, rad.
    window_s : float
        Averaging window of the heading (one synthetic aperture), s.
    overlap_s : float
        How far a segment started at a deviation cut reaches back before it (and the old
        one runs on past it), s; 0: segments meet at the cut without overlap.
    """

    deviation_m: float
    turn_rad: float
    window_s: float
    overlap_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("deviation_m", "turn_rad", "window_s"):
            value = getattr(self, name)
            if not value > 0.0:
                raise ProcessingError(f"SegmentLimits: {name} {value!r} is not > 0")
        if not self.overlap_s >= 0.0:
            raise ProcessingError(f"SegmentLimits: overlap_s {self.overlap_s!r} is not >= 0")

    @property
    def overlap_ns(self) -> int:
        """``overlap_s`` in ns (the pulses' time unit)."""
        return round(self.overlap_s * 1e9)


@dataclass(frozen=True)
class SegmentPlan:
    """What :meth:`Segmenter.plan` decided for one block of pulses.

    Attributes
    ----------
    turn : ndarray of bool, shape (P,)
        Pulses in a turn (not to be imaged).
    starts : ndarray of int64, shape (N,)
        Rows where a new segment starts (increasing, never a turn row).
    tracks : tuple of ReferenceTrack
        The reference track of each new segment (origin: the APC at its first pulse,
        NED relative to the APC at the Segmenter's first pulse, m; for a segment that
        overlaps the one before, its first pulse is up to ``overlap_s`` before its row in
        ``starts``, at ``t0_ns``).
    cut_x_m : ndarray of float64, shape (N,)
        For a segment that overlaps the one before (a deviation cut): imaging-frame x of
        the APC at its row in ``starts`` (the cut), m; NaN for one that does not.
    offset_m : ndarray of float64, shape (N, 3)
        APC at the segment's first pulse (``t0_ns``) minus the reference APC there,
        imaging frame (Δx, ΔY, ΔZ), m; zero for one that does not overlap.
    """

    turn: BoolArray
    starts: IntArray
    tracks: tuple[ReferenceTrack, ...]
    cut_x_m: FloatArray
    offset_m: FloatArray


def _heading(vel_ned: FloatArray) -> FloatArray:
    """Heading of horizontal velocities, rad from north toward east."""
    return np.asarray(np.arctan2(vel_ned[:, 1], vel_ned[:, 0]), dtype=np.float64)


def _wrap(angle: FloatArray) -> FloatArray:
    """Angles wrapped to (-π, π], rad."""
    return np.asarray(np.angle(np.exp(1j * angle)), dtype=np.float64)


def _inputs(
    t_ns: IntArray,
    vel_ned: FloatArray,
    known: BoolArray | None,
    after_skip: BoolArray | None,
    body_heading_rad: FloatArray | None,
) -> tuple[IntArray, FloatArray, BoolArray, BoolArray, FloatArray]:
    """:meth:`Segmenter.plan`'s arguments as arrays, the optional ones filled in (all
    known, no skip, no attitude); raises :class:`ProcessingError` where shapes disagree."""
    t = np.asarray(t_ns, dtype=np.int64)
    v = np.asarray(vel_ned, dtype=np.float64)
    ok = np.ones(t.shape[0], dtype=bool) if known is None else np.asarray(known, dtype=bool)
    skip = np.zeros(t.shape, bool) if after_skip is None else np.asarray(after_skip, bool)
    body = (
        np.full(t.shape, np.nan)
        if body_heading_rad is None
        else np.asarray(body_heading_rad, dtype=np.float64)
    )
    if v.shape != (t.shape[0], 3) or not ok.shape == skip.shape == body.shape == t.shape:
        raise ProcessingError(
            f"Segmenter: t_ns {t.shape}, vel_ned {v.shape}, known {ok.shape}, "
            f"after_skip {skip.shape} and body_heading_rad {body.shape} disagree"
        )
    return t, v, ok, skip, body


class Segmenter:
    """Streaming segmentation of a strip (see the module docstring).

    Parameters
    ----------
    limits : SegmentLimits
        Tolerances.
    track : ReferenceTrack
        Track of the first segment (its ``t0_ns`` is the first pulse).
    look_side : {"right", "left"}
        Side the antenna looks to (for the new tracks).
    """

    def __init__(self, limits: SegmentLimits, track: ReferenceTrack, look_side: LookSide) -> None:
        self.limits = limits
        self.track = track
        self.look_side: LookSide = look_side
        self._disp = LosState()
        self._pos = LosState(last_vel_yz=np.zeros(3), disp_yz_m=np.zeros(3))
        self._restart = False
        """A segment starts at the next pulse that is not in a turn."""
        self._seg_sum = np.zeros(3)
        self._seg_n = 0
        """Sum and count of the velocities of the current segment's pulses so far."""
        self._t = np.zeros(0, dtype=np.int64)
        self._v = np.zeros((0, 3))
        self._psi = np.zeros(0)
        self._body = np.zeros((0, 2))
        """(cos, sin) of the body's heading of the pulses in history (0, 0: no attitude)."""
        self._body_psi = np.zeros(0)
        """Window-mean body heading of the pulses in history, rad (NaN: no attitude)."""
        self._known = np.zeros(0, dtype=bool)
        self._last_known_ns = track.t0_ns
        """Time of the last pulse with navigation so far, GPS ns."""
        self._first_ns = track.t0_ns
        """Time of the first pulse, GPS ns: windows reaching before it are partial."""
        self._since_ns = track.t0_ns
        """Time of the current segment's start (its cut, before any reach back), GPS ns."""
        self._lead = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
        """Times (GPS ns) and APCs (NED, m) of the current segment's pulses within
        ``overlap_s`` of the last one (where an overlapping segment may start)."""

    def plan(
        self,
        t_ns: IntArray,
        vel_ned: FloatArray,
        known: BoolArray | None = None,
        after_skip: BoolArray | None = None,
        body_heading_rad: FloatArray | None = None,
    ) -> SegmentPlan:
        """Decide turns and segment starts for the next block and advance the state.

        Parameters
        ----------
        t_ns : ndarray of int64, shape (P,)
            Pulse times, strictly increasing across calls, GPS ns.
        vel_ned : ndarray of float64, shape (P, 3)
            APC velocity at the pulses, NED, m/s.
        known : ndarray of bool, shape (P,), optional
            Pulses whose velocity is measured (false: a placeholder across a navigation
            gap); all when omitted.
        after_skip : ndarray of bool, shape (P,), optional
            Pulses that follow pulses the caller skipped (with navigation, not given
            here): the hole before them never starts a segment. None: no skip.
        body_heading_rad : ndarray of float64, shape (P,), optional
            Heading of the body's x axis at the pulses, rad from north toward east (NaN: no
            attitude). A turn needs the body's window-mean heading to turn as the course's
            did; where it is not known (None, or a window without attitude), the course
            alone decides.
        """
        t, v, ok, skip, body = _inputs(t_ns, vel_ned, known, after_skip, body_heading_rad)
        if t.size == 0:
            return SegmentPlan(
                np.zeros(0, bool), np.zeros(0, np.int64), (), np.zeros(0), np.zeros((0, 3))
            )
        pos, self._pos = integrate_los(t, v, self._pos)
        mean_v, turn = self._windowed(t, v, ok, body)
        gap = self._after_gap(t, ok) & ~skip
        starts: list[int] = []
        tracks: list[ReferenceTrack] = []
        cut_x: list[float] = []
        offsets: list[FloatArray] = []
        k, n = 0, t.size
        while k < n:
            if turn[k]:
                self._restart = True
                self._keep_lead(t[:0], pos[:0], fresh=True)
                k += int(np.argmin(turn[k:])) if not turn[k:].all() else n - k
                continue
            if gap[k] or self._restart:  # no overlap: nothing usable before
                velocity = self._ahead(t, v, ok, k) if gap[k] else mean_v[k]
                self._start(k, t, velocity, pos, starts, tracks)
                cut_x.append(np.nan)
                offsets.append(np.zeros(3))
                self._keep_lead(t[:0], pos[:0], fresh=True)
            cut = turn[k:] | gap[k:]
            cut[0] = False
            end = k + (int(np.argmax(cut)) if cut.any() else n - k)
            vel_img = vector_to_imaging(v[k:end], self.track)[:, 1:3]
            disp, state = integrate_los(t[k:end], vel_img, self._disp)
            over = np.flatnonzero(
                (np.hypot(disp[:, 0], disp[:, 1]) > self.limits.deviation_m) & ok[k:end]
            )
            if over.size:  # a segment starts there (its deviation restarts at 0)
                m = k + int(over[0])
                seg_n = self._seg_n + int(ok[k:m].sum())
                long_v = (self._seg_sum + v[k:m][ok[k:m]].sum(axis=0)) / max(seg_n, 1)
                use_long = seg_n > 0 and (t[m] - self._since_ns) * 1e-9 > self.limits.window_s
                self._keep_lead(t[k:m], pos[k:m])
                velocity = long_v if use_long else mean_v[m]
                self._start(m, t, velocity, pos, starts, tracks)
                x, offset = self._reach_back(m, t, pos, tracks)
                cut_x.append(x)
                offsets.append(offset)
                k = m
                continue
            self._disp = state
            self._seg_sum += v[k:end][ok[k:end]].sum(axis=0)
            self._seg_n += int(ok[k:end].sum())
            self._keep_lead(t[k:end], pos[k:end])
            k = end
        return SegmentPlan(
            turn,
            np.asarray(starts, dtype=np.int64),
            tuple(tracks),
            np.asarray(cut_x, dtype=np.float64),
            np.asarray(offsets, dtype=np.float64).reshape(-1, 3),
        )

    def _keep_lead(self, t: IntArray, pos: FloatArray, fresh: bool = False) -> None:
        """Add the current segment's pulses (``fresh``: after a new start or a turn, forget
        the ones before) and keep those within ``overlap_s`` of the last."""
        if self.limits.overlap_s <= 0.0:
            return
        old_t, old_pos = (t[:0], pos[:0]) if fresh else self._lead
        lead_t, lead_pos = np.concatenate([old_t, t]), np.concatenate([old_pos, pos])
        if lead_t.size:
            keep = lead_t >= lead_t[-1] - self.limits.overlap_ns
            lead_t, lead_pos = lead_t[keep], lead_pos[keep]
        self._lead = (lead_t, lead_pos)

    def _reach_back(
        self, m: int, t: IntArray, pos: FloatArray, tracks: list[ReferenceTrack]
    ) -> tuple[float, FloatArray]:
        """Move the origin of the segment just started at the deviation cut at row ``m``
        back along its track to the first pulse kept within ``overlap_s`` before it (none
        kept: it stays at the cut). Returns the cut's imaging-frame x on it (NaN: it does
        not overlap), m, and the APC's offset from it at its first pulse, m."""
        lead_t, lead_pos = self._lead
        rows = lead_t >= t[m] - self.limits.overlap_ns
        first = int(np.argmax(rows)) if rows.any() else lead_t.size
        self._lead = (lead_t[first:], lead_pos[first:])
        if first == lead_t.size:
            return float("nan"), np.zeros(3)
        back_m = self.track.v0_mps * (t[m] - lead_t[first]) * 1e-9
        self.track = replace(
            self.track,
            origin_ned=self.track.origin_ned - back_m * self.track.x_hat,
            t0_ns=int(lead_t[first]),
        )
        tracks[-1] = self.track
        return back_m, ned_to_imaging(lead_pos[first], self.track)

    def _start(
        self,
        k: int,
        t: IntArray,
        velocity: FloatArray,
        pos: FloatArray,
        starts: list[int],
        tracks: list[ReferenceTrack],
    ) -> None:
        """Begin a segment at row ``k``: a track along ``velocity`` (NED, m/s) from there."""
        self.track = ReferenceTrack.from_velocity(pos[k], velocity, int(t[k]), self.look_side)
        self._disp = LosState()
        self._seg_sum = np.zeros(3)
        self._seg_n = 0
        self._restart = False
        self._since_ns = int(t[k])
        starts.append(k)
        tracks.append(self.track)

    def _windowed(
        self, t: IntArray, v: FloatArray, known: BoolArray, body_rad: FloatArray
    ) -> tuple[FloatArray, BoolArray]:
        """Window-mean velocity of the known pulses (P, 3) (of all where the window holds
        none) and the turn mask (P,) of the block (from all pulses: the placeholders across
        a gap are smooth; the body's heading where known); keeps the history."""
        w_ns = round(self.limits.window_s * 1e9)
        n_hist = self._t.size
        t_all = np.concatenate([self._t, t])
        v_all = np.concatenate([self._v, v])
        k_all = np.concatenate([self._known, known])
        lit = np.isfinite(body_rad)
        unit = np.where(lit[:, None], np.column_stack([np.cos(body_rad), np.sin(body_rad)]), 0.0)
        b_all = np.concatenate([self._body, unit])
        rows = np.arange(n_hist, t_all.size)
        first = np.searchsorted(t_all, t_all[rows] - w_ns, side="right")

        def window_sum(x: FloatArray) -> FloatArray:
            cum = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
            return np.asarray(cum[rows + 1] - cum[first], dtype=np.float64)

        mean_v = window_sum(v_all) / (rows + 1 - first)[:, None]
        n_known = window_sum(k_all[:, None].astype(np.float64))
        known_v = window_sum(v_all * k_all[:, None]) / np.maximum(n_known, 1.0)
        psi_all = np.concatenate([self._psi, _heading(mean_v)])
        body_sum = window_sum(b_all)
        body_new = np.where(
            np.any(body_sum != 0.0, axis=1), np.arctan2(body_sum[:, 1], body_sum[:, 0]), np.nan
        )
        body_all = np.concatenate([self._body_psi, body_new])
        earlier = np.maximum(first - 1, 0)
        full = t_all[earlier] - w_ns >= self._first_ns  # the window one earlier is whole
        course = np.abs(_wrap(psi_all[rows] - psi_all[earlier])) > self.limits.turn_rad
        body_turn = np.abs(_wrap(body_all[rows] - body_all[earlier]))
        body_ok = ~np.isfinite(body_turn) | (body_turn > self.limits.turn_rad)
        turn = full & course & body_ok
        keep = t_all > t_all[-1] - 2 * w_ns - 1
        self._t, self._v, self._psi = t_all[keep], v_all[keep], psi_all[keep]
        self._body, self._body_psi = b_all[keep], body_all[keep]
        self._known = k_all[keep]
        return np.where(n_known > 0, known_v, mean_v), np.asarray(turn, dtype=bool)

    def _after_gap(self, t: IntArray, known: BoolArray) -> BoolArray:
        """Known pulses (P,) more than ``window_s`` after the known pulse before them."""
        rows = np.flatnonzero(known)
        prev = np.concatenate([[self._last_known_ns], t[rows[:-1]]])
        gap = np.zeros(t.size, dtype=bool)
        gap[rows] = t[rows] - prev > round(self.limits.window_s * 1e9)
        if rows.size:
            self._last_known_ns = int(t[rows[-1]])
        return gap

    def _ahead(self, t: IntArray, v: FloatArray, known: BoolArray, k: int) -> FloatArray:
        """Mean velocity of the known pulses from row ``k`` over ``window_s`` (as far as the
        block goes), NED, m/s (row ``k`` is known)."""
        end = int(np.searchsorted(t, t[k] + round(self.limits.window_s * 1e9)))
        ahead = v[k:end][known[k:end]]
        return np.asarray(ahead.mean(axis=0), dtype=np.float64)
