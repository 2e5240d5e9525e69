"""The streaming focusing chain of the daemon, configured from :class:`Config`.

Per block of aligned pulses: range compression → INS-only compensation
(D_los, docs/methods.md §2) → sliding-subaperture autofocus (docs/methods.md §3, optional) →
azimuth pre-filter (low-pass and decimate in slow time to the Doppler band of
the culled beam, optional) → backprojection onto ground tiles. Every stage is a
processing object with its own carried state, so a live run and a replay of the
same pulses give the same products.

The strip is cut into segments (:mod:`sarmoco.processing.segments`): the first
reference track is the straight line at the velocity it is given (the pipeline's mean
over ``mocomp.heading_window_s`` of flight, docs/methods.md §1); after each turn, and
wherever the INS track leaves the current line by ``mocomp.segment_tolerance_m``, the
segment's autofocus is flushed, its tiles are closed, and a new segment starts with a new
track, a new D_los (from 0), a new autofocus and a new tile imager. Pulses in turns are
not imaged (the pipeline flags them ``TURN``).

At a deviation cut (not after a turn or a navigation gap) the two segments overlap, so
that a target whose aperture straddles the cut is still imaged from one track with its
whole aperture: the new segment's track begins up to ``overlap_s`` (the imaged beam's
half footprint at far range over v0, plus 10 %) before the cut, and it is first fed the
pulses of that stretch again (the focuser keeps the last ``overlap_s`` of pulses it
pushed); the old segment takes the pulses up to ``overlap_s`` past the cut, then ends.
The cut line on the ground (where the beam centre sees the ground at the cut: normal to
the new track through the APC for a broadside beam, ``rho tan(psi)`` along it for a beam
squinted by ``psi``, ``rho`` the distance from the track, taken linear across the swath) splits
their tiles (:attr:`TileLayout.keep`): the old segment keeps the pixels before it, the new
one those after it, so no target is imaged twice and none falls between. The new
segment's tiles are handed out after the old segment's last (tiles come out segment by
segment, as a batch stores them).

A live focuser that falls behind skips recorded pulses (the daemon's focus backlog); the
pulses after such a skip continue the segment (``after_skip``): its track, D_los, beam
and tile imager (with the range-Doppler filters of its block shape) carry across the
hole, whose tiles are simply not formed live; the autofocus and the pre-filter end their
runs at the hole and start new ones after it, as at any gap longer than their windows.
Starting a segment there would spend on closing one segment and opening the next the
time the focuser was short of, and fall further behind.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Protocol

import numpy as np

from sarmoco.daemon.config import Config
from sarmoco.daemon.livelevel import LiveLevel
from sarmoco.processing import rangecomp
from sarmoco.processing.autofocus import (
    AutofocusGeometry,
    SlidingSubapertureAutofocus,
)
from sarmoco.processing.beam import (
    DopplerCentroid,
    accc_coherence,
    accc_correlation,
    array_axis_body,
    array_axis_imaging,
    centre_squint_rad,
    correlation_centroid_hz,
    doppler_hz,
    echoes_stand_out,
    resolve_ambiguity,
    squint_interval_rad,
    squint_sine,
    within_band,
)
from sarmoco.processing.geometry import (
    ReferenceTrack,
    body_heading_rad,
    look_angle,
    vector_to_imaging,
)
from sarmoco.processing.imaging.pfa_tiles import PfaTileImager
from sarmoco.processing.imaging.presum import AzimuthPrefilter, fill_slots, slot_steps
from sarmoco.processing.imaging.rda_tiles import RdaTileImager
from sarmoco.processing.imaging.tile_pga import StripPga, TilePga
from sarmoco.processing.imaging.tiles import Tile, TileImager, TileLayout
from sarmoco.processing.mocomp import (
    InsMotionCompensator,
    LosGeometry,
    LosState,
    MocompSolution,
    correct_los,
    integrate_los,
    los_solution,
    remove_centre_phase,
)
from sarmoco.processing.segments import Segmenter, SegmentLimits
from sarmoco.processing.types import BoolArray, ComplexArray, FloatArray, IntArray, RadarParams


@dataclass
class FocusOutput:
    """What one step of the chain produced.

    Attributes
    ----------
    motion : MocompSolution or None
        INS motion solution of the pulses pushed (None from :meth:`Focuser.finish`);
        NaN for pulses in turns (not compensated).
    tiles : list of Tile
        Image tiles finished in this step.
    tracks : list of ReferenceTrack
        The reference track of each tile (same order as ``tiles``): the tile's axes are
        metres in that track's imaging frame.
    turn : ndarray of bool, shape (P,)
        Pulses pushed that are in a turn and were not imaged (empty from finish).
    """

    motion: MocompSolution | None = None
    tiles: list[Tile] = field(default_factory=list)
    tracks: list[ReferenceTrack] = field(default_factory=list)
    turn: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    doppler: list[DopplerCentroid] = field(default_factory=list)

    def add_tiles(self, tiles: list[Tile], track: ReferenceTrack) -> None:
        """Append tiles formed on ``track``."""
        self.tiles += tiles
        self.tracks += [track] * len(tiles)


class TileSink(Protocol):
    """What a segment's focused pulses go to: a :class:`TileImager`, or a stand-in that
    keeps them for imaging elsewhere (a batch images blocks of tiles on other workers)."""

    def add(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None = None,
        beam_squint_rad: FloatArray | None = None,
    ) -> list[Tile]:
        """Take pulses ready for backprojection (see :meth:`TileImager.add`); finished tiles."""

    def close(self) -> list[Tile]:
        """End of the segment: the tiles still open."""


TileFormer = TileImager | RdaTileImager | PfaTileImager
"""A segment's tile imager: backprojection (direct or FFBP), range-Doppler or polar format."""

LIVE_IMAGERS = (RdaTileImager, PfaTileImager)
"""The tile imagers whose tiles a live run may degrade (:mod:`sarmoco.daemon.livelevel`)."""

SinkFactory = Callable[[TileFormer, ReferenceTrack], TileSink]
"""Makes a segment's sink from the imager it would use and its reference track."""


def tile_layout(cfg: Config) -> TileLayout:
    """Where a segment's tiles lie (the whole strip: no ``keep``)."""
    geo, im = cfg.geometry, cfg.imaging
    ground_range = math.sqrt(max(geo.center_slant_range_m**2 - geo.height_m**2, 0.0))
    return TileLayout(
        height_m=geo.height_m,
        ground_range_m=ground_range,
        swath_m=im.swath_m,
        tile_length_m=im.tile_length_m,
        pixel_m=im.pixel_m,
        beamwidth_rad=cfg.imaging.imaged_beam_rad(),
    )


def tile_imaging(cfg: Config, radar: RadarParams) -> tuple[TileFormer, TilePga | None]:
    """A segment's tile imager (``imaging.method``) and tile PGA (None when
    ``autofocus.pga`` is off)."""
    geo, im, af = cfg.geometry, cfg.imaging, cfg.autofocus
    beam_rad = cfg.imaging.imaged_beam_rad()
    imager: TileFormer
    if im.method == "rda":
        imager = RdaTileImager(tile_layout(cfg), rangecomp.range_axis_m(radar), radar.wavelength_m)
    elif im.method == "pfa":
        imager = PfaTileImager(
            tile_layout(cfg),
            rangecomp.range_axis_m(radar),
            radar.wavelength_m,
            radar.bandwidth_hz,
            math.radians(im.azimuth_beamwidth_deg),
        )
    else:
        imager = TileImager(
            tile_layout(cfg),
            rangecomp.range_axis_m(radar),
            radar.wavelength_m,
            ffbp_budget_rad=im.ffbp_max_phase_error_rad if im.method == "ffbp" else None,
        )
    tile_pga = (
        TilePga(
            StripPga(
                geo.height_m,
                radar.wavelength_m,
                beam_rad / 2.0,
                settings=af,
                guard_m=10.0 * radar.range_resolution_m,
            )
        )
        if af.pga
        else None
    )
    return imager, tile_pga


class _Segment:
    """INS compensation, autofocus, pre-filter and tiles of one straight reference track.

    ``sink`` (optional) takes the pulses the tile imager would backproject; tile PGA is
    then left to whoever images them.
    """

    def __init__(
        self,
        cfg: Config,
        radar: RadarParams,
        track: ReferenceTrack,
        sink: SinkFactory | None = None,
        offset_m: FloatArray | None = None,
        quat: FloatArray | None = None,
    ) -> None:
        self.track = track
        start = np.zeros(3) if offset_m is None else np.asarray(offset_m, dtype=np.float64)
        geo, im, af = cfg.geometry, cfg.imaging, cfg.autofocus
        range_m = rangecomp.range_axis_m(radar)
        los = LosGeometry.build(
            radar,
            range_m,
            geo.height_m,
            geo.center_slant_range_m,
            order=cfg.mocomp.order,
            envelope_fraction=cfg.mocomp.envelope_fraction,
        )
        self.mocomp = InsMotionCompensator(track, los, LosState(disp_yz_m=start[1:].copy()))
        self._along: LosState | None = (
            LosState(last_vel_yz=np.zeros(1), disp_yz_m=start[:1].copy())
            if cfg.mocomp.along_track
            else None
        )
        self._last_tau_ns: int | None = None
        self._eq29 = not af.enabled
        """Whether the imager removes each pixel's squint residual (eq. 29) of the compensation.

        Not with the autofocus on: it measures that residual as a Doppler-rate error
        (γ0 ΔY / dy on a line at ground range dy) and corrects it with the rest, so the
        imager would remove it twice (ku-microuav ×0.1, 4 m sidestep: -11.9 dB azimuth PSLR
        with both, -13.0 with the autofocus alone, -13.3 with the imager alone).
        """
        self._dy_t_ns = np.zeros(0, np.int64)
        self._dy_m = np.zeros(0)
        """Imaging time (GPS ns) and compensated ΔY (m) of the pulses not yet imaged (eq. 29)."""
        self._slot_ns: int | None = None
        """Time of the last pulse given to the autofocus, GPS ns."""
        self._period_ns = round(1e9 / radar.prf_hz)
        self._max_fill_slots = max(1, round(af.subaperture_s * radar.prf_hz))
        self.autofocus = (
            SlidingSubapertureAutofocus(
                AutofocusGeometry(
                    radar.wavelength_m, track.v0_mps, geo.height_m, geo.center_slant_range_m
                ),
                range_m,
                af,
            )
            if af.enabled
            else None
        )
        imager, self.tile_pga = tile_imaging(cfg, radar)
        self.imager: TileSink = imager
        self.tiles = imager
        """The tile imager whose layout says which tiles and pixels the segment forms (its
        sink's too)."""
        self.held: list[Tile] = []
        """Finished tiles waiting for the segments before this one to end."""
        if sink is not None:
            self.imager, self.tile_pga = sink(imager, track), None
        self.beam = _Beam(cfg, radar, track, imager.layout)
        if quat is not None:
            self.beam.point(quat, track.t0_ns)
        f_lo, f_hi = self.beam.band_hz()
        self.prefilter = (
            AzimuthPrefilter(radar.prf_hz, (f_hi - f_lo) / 2.0, im.prefilter_oversampling)
            if im.prefilter and f_hi > f_lo
            else None
        )
        self._point_stages()
        self.presum_first = im.presum_first and self.prefilter is not None
        """The pre-filter runs on raw echoes, before range compression (``imaging.presum_first``):
        pushed pulses are raw, and everything after the pre-filter runs at its output rate."""
        if self.presum_first:
            assert self.prefilter is not None
            d = self.prefilter.decimation
            self._period_ns = round(1e9 * d / radar.prf_hz)
            self._max_fill_slots = max(1, round(af.subaperture_s * radar.prf_hz / d))
        self._radar = radar
        self._window = None if im.window == "none" else im.window
        self._disp_t_ns = np.zeros(0, np.int64)
        self._disp_m = np.zeros((0, 2))
        """Imaging time (GPS ns) and (ΔY, ΔZ) (m) of raw pulses not yet range-compressed."""

    @property
    def tile_layout(self) -> TileLayout:
        """Where the segment's tiles lie (with the ground it keeps)."""
        return self.tiles.layout

    def keep(self, a: float, b: float, c: float) -> None:
        """Image only the ground where ``a x + b y < c`` (imaging x, y, m) from now on."""
        layout = self.tiles.layout
        self.tiles.layout = replace(layout, keep=(*layout.keep, (a, b, c)))

    def _point_stages(self) -> None:
        """Centre the pre-filter's band and the autofocus's lines on the beam's pointing."""
        if self.prefilter is not None:
            self.prefilter.centroid_hz = self.beam.centroid_hz
        if self.autofocus is not None:
            self.autofocus.geometry = replace(
                self.autofocus.geometry, squint_rad=self.beam.scene_squint_rad
            )

    def push(
        self,
        pulses: ComplexArray,
        t_ns: IntArray,
        vel_ned: FloatArray,
        quat: FloatArray | None = None,
    ) -> tuple[MocompSolution, list[Tile]]:
        """Compensate, autofocus and image pulses of this segment.

        ``pulses`` are range-compressed, or raw with :attr:`presum_first` (then: the
        scene-centre D_los phase per pulse, the pre-filter, range compression, and the
        envelope shift and per-bin D_los at the pre-filter's output times). ``quat``: the
        pulses' attitude (body to NED), which points the beam for them (unchanged without).
        """
        if quat is not None and t_ns.size:
            self.beam.point(quat, int(t_ns[0]))
            self._point_stages()
        if self.presum_first:
            motion = los_solution(
                t_ns, self.mocomp.displacement(t_ns, vel_ned), self.mocomp.geometry
            )
            raw = remove_centre_phase(pulses, motion.phase_rad, self._radar.iq_conjugate)
        else:
            rc, motion = self.mocomp.compensate(pulses, t_ns, vel_ned)
        t_ns = self._along_track_time(t_ns, vel_ned)
        if self._eq29:
            self._dy_t_ns = np.concatenate([self._dy_t_ns, t_ns])
            self._dy_m = np.concatenate([self._dy_m, motion.disp_yz_m[:, 0]])
        if self.presum_first:
            assert self.prefilter is not None
            self._disp_t_ns = np.concatenate([self._disp_t_ns, t_ns])
            self._disp_m = np.concatenate([self._disp_m, motion.disp_yz_m])
            return motion, self._compress_focus(*self.prefilter.push(raw, t_ns))
        return motion, self._focus(rc, t_ns)

    def _focus(self, rc: ComplexArray, t_ns: IntArray) -> list[Tile]:
        """Autofocus (when on) and image compensated, range-compressed pulses; measure their
        Doppler centroid."""
        self.beam.measure(rc, t_ns, 1e9 / self._period_ns)
        self._point_stages()
        if self.autofocus is None:
            return self._image(rc, t_ns)
        return self._autofocus_image(rc, t_ns)

    def _compress_focus(self, raw: ComplexArray, t_ns: IntArray) -> list[Tile]:
        """Range-compress pre-filtered raw pulses, shift their envelopes, remove the per-bin
        D_los (``mocomp.order`` 2), then autofocus and image them (:attr:`presum_first`).

        (ΔY, ΔZ) (smooth) is interpolated to the pre-filter's output times from the raw
        pulses'; those before the last output are then dropped.
        """
        if t_ns.size == 0:
            return []
        rc = rangecomp.compress(self._radar, raw, self._window)
        base = self.track.t0_ns
        t_rel, held = t_ns - base, self._disp_t_ns - base
        disp = np.stack([np.interp(t_rel, held, self._disp_m[:, k]) for k in (0, 1)], axis=1)
        keep = max(0, int(np.searchsorted(self._disp_t_ns, t_ns[-1], side="right")) - 1)
        self._disp_t_ns, self._disp_m = self._disp_t_ns[keep:], self._disp_m[keep:]
        rc, _ = correct_los(rc, t_ns, disp, self.mocomp.geometry, centre_phase=False)
        return self._focus(rc, t_ns)

    def _autofocus_image(self, rc: ComplexArray, t_ns: IntArray) -> list[Tile]:
        """Autofocus and image pulses, with zero rows in the PRF slots of missing ones.

        The autofocus estimates Doppler rates with FFTs over the pulses of a subaperture,
        taken as uniformly spaced: a lost datagram that left no hole would shift every
        later pulse of the subaperture by a PRI (2 % loss: -13.1 -> -10.4..-11.1 dB
        azimuth PSLR on ku-vehicle x0.1). Gaps up to a subaperture are filled; a longer
        one (an outage, an overload) ends the autofocus run: it is flushed and a new one
        starts with the next pulse, so that no subaperture falls into the gap (it had no
        pulse to estimate from).
        """
        assert self.autofocus is not None
        if t_ns.size == 0:
            return []
        last = self._slot_ns if self._slot_ns is not None else int(t_ns[0]) - self._period_ns
        steps = slot_steps(t_ns, last, self._period_ns)
        long_gaps = np.flatnonzero(steps > self._max_fill_slots)
        if long_gaps.size:
            g = int(long_gaps[0])
            tiles = self._autofocus_image(rc[:g], t_ns[:g])
            engine = self.autofocus
            focused, corr = engine.flush()
            tiles += self._image(focused, corr.t_ns)
            self.autofocus = SlidingSubapertureAutofocus(
                engine.geometry, engine.range_m, engine.config
            )
            self.autofocus.report = engine.take_report()  # estimates not recorded yet
            self._slot_ns = None
            return tiles + self._autofocus_image(rc[g:], t_ns[g:])
        self._slot_ns = int(t_ns[-1])
        steps[steps < 1] = 1
        focused, corr = self.autofocus.push(*fill_slots(rc, t_ns, steps, last))
        return self._image(focused, corr.t_ns)

    def finish(self) -> list[Tile]:
        """Release what autofocus and the pre-filter still hold; close every tile."""
        tiles: list[Tile] = []
        if self.presum_first:
            assert self.prefilter is not None
            tiles = self._compress_focus(*self.prefilter.flush())
        if self.autofocus is not None:
            focused, corr = self.autofocus.flush()
            tiles += self._image(focused, corr.t_ns)
        if self.prefilter is not None and not self.presum_first:
            tiles += self._backproject(*self.prefilter.flush())
        return tiles + self._refine(self.imager.close(), last=True)

    def _along_track_time(self, t_ns: IntArray, vel_ned: FloatArray) -> IntArray:
        """Slow time of each pulse from its INS along-track position: t0 + x / v0, GPS ns.

        Autofocus and backprojection assume the reference track's uniform speed v0 (nominal
        Doppler rate 2 v0² / (λ R), APC at v0 t along track). An along-track speed that
        differs from v0 (a start-up speed estimate off by 0.2 %, gusts of 0.1 m/s rms) is
        then a Doppler-rate error no LOS term explains and an along-track position error
        of centimetres: both defocus. Giving every pulse the time at which the reference
        track passes its actual along-track position (x from the trapezoid-integrated INS
        along-track velocity) removes both; the LOS compensation uses the true times.
        Unchanged times when ``mocomp.along_track`` is false.
        """
        if self._along is None or t_ns.size == 0:
            return t_ns
        v_along = vector_to_imaging(vel_ned, self.track)[:, :1]
        x, self._along = integrate_los(t_ns, v_along, self._along)
        tau = self.track.t0_ns + np.round(x[:, 0] / self.track.v0_mps * 1e9).astype(np.int64)
        # strictly increasing (a pulse never passes the one before), at least 1 ns apart
        steps = np.arange(tau.size, dtype=np.int64)
        floor = self._last_tau_ns + 1 if self._last_tau_ns is not None else tau[0]
        tau = np.maximum.accumulate(np.maximum(tau, floor) - steps) + steps
        self._last_tau_ns = int(tau[-1])
        return tau

    def _image(self, rc: ComplexArray, t_ns: IntArray) -> list[Tile]:
        if self.prefilter is not None and not self.presum_first:
            rc, t_ns = self.prefilter.push(rc, t_ns)
        return self._backproject(rc, t_ns)

    def _backproject(self, rc: ComplexArray, t_ns: IntArray) -> list[Tile]:
        if rc.shape[0] == 0:
            return []
        apc = self.track.position_imaging(t_ns)
        dy, beam = self._compensated_dy(t_ns), self.beam.interval_at(t_ns)
        if self.prefilter is not None and self.prefilter.decimation > 1:
            band = self.prefilter.passband_hz(t_ns)
            beam = within_band(beam, band, self.track.v0_mps, self._radar.wavelength_m)
        return self._refine(self.imager.add(rc, t_ns, apc, dy, beam))

    def _compensated_dy(self, t_ns: IntArray) -> FloatArray | None:
        """ΔY the pulses imaged at ``t_ns`` were compensated for, m (None: no eq. 29 term).

        The autofocus fills lost PRF slots and the pre-filter puts its outputs on slot
        centres, so ΔY (smooth) is interpolated to these times from the compensated
        pulses' (held beyond the ends); the pulses before the last time asked for are
        then dropped (imaging times only increase).
        """
        if not self._eq29:
            return None
        base = self.track.t0_ns
        dy = np.interp(t_ns - base, self._dy_t_ns - base, self._dy_m)
        keep = max(0, int(np.searchsorted(self._dy_t_ns, t_ns[-1], side="right")) - 1)
        self._dy_t_ns, self._dy_m = self._dy_t_ns[keep:], self._dy_m[keep:]
        return dy

    def _refine(self, tiles: list[Tile], last: bool = False) -> list[Tile]:
        """Finished tiles through tile PGA when configured (``last``: hand out all it holds)."""
        if self.tile_pga is None:
            return tiles
        span = self.beam.span_rad
        return self.tile_pga.push(tiles, span) + (self.tile_pga.flush(span) if last else [])


MIN_COHERENCE = 0.1
"""Blocks whose echoes correlate less from pulse to pulse (:func:`accc_coherence`) are left
out of the segment's echo centroid: noise alone (no scene in the beam yet) gives about
``1 / sqrt(pulses x bins)``, a scene's echoes tenths to 1."""

MIN_STANDOUT = 2.0
"""A block whose echoes correlate too little for a centroid keeps the pointing uncertainty's
wider beam only when some range bin's power, summed over its pulses, exceeds the median
bin's this many times (:func:`~sarmoco.processing.beam.echoes_stand_out`): a target entering
the beam does (its few lit pulses sit in one bin), noise alone stays within about 1.3 times
at 128 pulses, and the wider beam would add only noise, at three times the imaging cost."""


class _Beam:
    """Where a segment's beam points, block by block, and its Doppler centroid.

    The antenna's array axis (``geometry.antenna_squint_deg``, fixed to the body) is turned
    by the mean attitude of each block of pulses into the segment's imaging frame
    (:mod:`sarmoco.processing.beam`). The pixels take the squint interval of the imaged
    beam (``imaging.azimuth_beamwidth_deg`` plus the squint tolerance each side, over the
    look angles of the swath) about the block's pointing, widened to cover that of the
    mean of the segment's blocks so far (the attitude wanders by tenths of a degree to a
    degree about a steady crab). Once the segment's echoes have given a Doppler centroid,
    the block's interval also covers the beam about it (an INS heading a degree off, an
    antenna that does not follow the body's every motion: the echoes show where the beam
    is; the attitude resolves its ambiguity). Until then, the interval is widened by
    ``imaging.pointing_uncertainty_deg`` on each side (the echoes of the first blocks,
    before the scene fills the beam, often correlate too little to say where it is), except
    for a block whose echoes are noise alone (:data:`MIN_STANDOUT`). The interval holds
    from the block's first pulse, for the pulses imaged later. The pre-filter keeps the
    Doppler band of the attitude's interval, centred on the echoes' centroid once
    measured; the autofocus's lines take the echoes' squint (else the attitude's). Each
    block's centroid from the attitude (at the reference look angle) and from its echoes
    go to the store (:attr:`centroids`). Before any attitude (and without one) the beam
    is broadside.
    """

    def __init__(
        self, cfg: Config, radar: RadarParams, track: ReferenceTrack, layout: TileLayout
    ) -> None:
        geo = cfg.geometry
        self._axis_body = array_axis_body(math.radians(geo.antenna_squint_deg), geo.look_side)
        self._track = track
        self._half_rad = cfg.imaging.imaged_beam_rad() / 2.0
        self._unsure_rad = math.radians(cfg.imaging.pointing_uncertainty_deg)
        """Widening of each side of a block's interval until the echoes give a centroid."""
        self._prf_hz = radar.prf_hz
        edges = layout.ground_range_m + np.array([-0.5, 0.5]) * layout.swath_m
        self._swath_look_rad = np.arctan2(edges, layout.height_m)
        self._scene_look_rad = float(look_angle(geo.center_slant_range_m, geo.height_m))
        self._ref_look_rad = cfg.geometry.reference_look_rad()
        self._speed_mps, self._wavelength_m = track.v0_mps, radar.wavelength_m
        self.axis = np.array([1.0, 0.0, 0.0])
        """Array axis of the latest block in the imaging frame (broadside: along track)."""
        self._axis_sum = np.zeros(3)
        """Sum of the blocks' array axes (their mean: the segment's steady pointing)."""
        self._changes_ns = np.zeros(1, np.int64)
        self._intervals = np.array([[-self._half_rad, self._half_rad]])
        """Times (GPS ns) from which each squint interval (rad) holds, and the intervals."""
        self._span = (math.inf, -math.inf)
        """Union of the squint intervals handed out by :meth:`interval_at`, rad."""
        self._attitude_interval = self._intervals[-1].copy()
        self._unwidened = (-self._half_rad, self._half_rad)
        """The latest block's interval before the pointing uncertainty's widening, rad."""
        self._attitude_squint_rad = 0.0
        """The latest block's squint interval and beam-centre squint at the scene centre
        from its attitude alone, rad."""
        self.centroids: list[DopplerCentroid] = []
        """Doppler centroids measured and not yet taken (:meth:`take_centroids`)."""
        self._pending: DopplerCentroid | None = None
        self._correlation = 0j
        """Pulse-to-pulse correlation of the segment's echoes so far (ACCC)."""
        self._echo_squint_rad: float | None = None
        """Squint of the centroid of that correlation, rad (None: not measured yet)."""

    @property
    def scene_squint_rad(self) -> float:
        """Squint of the beam centre at the scene centre's look angle, rad: that of the
        segment's echoes once measured (where the echoes' energy is, what the autofocus's
        lines see), else the attitude's."""
        if self._echo_squint_rad is not None:
            return self._echo_squint_rad
        return float(centre_squint_rad(self.axis, self._scene_look_rad))

    @property
    def span_rad(self) -> tuple[float, float]:
        """Union of the squint intervals the segment's pixels took pulses over so far, rad
        (lo, hi): the beam's band tile PGA keeps (broadside before any pulse is imaged)."""
        lo, hi = self._span
        return (lo, hi) if lo < hi else (-self._half_rad, self._half_rad)

    def point(self, quat: FloatArray, t_ns: int) -> None:
        """Point the beam by the mean attitude ``quat`` (P, 4) of the pulses from ``t_ns``
        (GPS ns) on; rows that are not finite are left out (none finite: unchanged)."""
        q = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
        if not np.all(np.isfinite(q), axis=1).any():
            return
        self.axis = array_axis_imaging(q, self._axis_body, self._track)
        self._axis_sum += self.axis
        mean = self._axis_sum / np.linalg.norm(self._axis_sum)
        lo, hi = squint_interval_rad(self.axis, self._half_rad, self._swath_look_rad)
        lo_m, hi_m = squint_interval_rad(mean, self._half_rad, self._swath_look_rad)
        self._attitude_interval = np.array([lo, hi])
        lo, hi = min(lo, lo_m), max(hi, hi_m)
        self._unwidened = (lo, hi)
        if self._echo_squint_rad is None:  # the echoes have not shown where the beam is
            lo, hi = self._widened(lo, hi)
        keep = self._changes_ns < t_ns
        self._changes_ns = np.append(self._changes_ns[keep], t_ns)
        self._intervals = np.vstack([self._intervals[keep], [lo, hi]])
        squint = float(centre_squint_rad(self.axis, self._ref_look_rad))
        self._attitude_squint_rad = float(centre_squint_rad(self.axis, self._scene_look_rad))
        f_dc = float(doppler_hz(self._speed_mps, self._wavelength_m, squint))
        self._pending = DopplerCentroid(t_ns, squint, f_dc, math.nan)

    def _widened(self, lo: float, hi: float) -> tuple[float, float]:
        """The squint interval ``(lo, hi)`` (rad) widened by the pointing uncertainty on
        each side, as far as its Doppler band stays within the pulse rate: a wider band
        would take a target lit at its low edge again, aliased, at its high edge (a ghost
        a pulse rate's worth of Doppler away)."""
        rate_sine = float(squint_sine(self._prf_hz, self._speed_mps, self._wavelength_m))
        room = max(0.0, (rate_sine - (math.sin(hi) - math.sin(lo))) / 2.0)
        low = max(lo - self._unsure_rad, math.asin(max(-1.0, math.sin(lo) - room)))
        high = min(hi + self._unsure_rad, math.asin(min(1.0, math.sin(hi) + room)))
        return low, high

    def band_hz(self) -> tuple[float, float]:
        """Doppler band of the latest block's beam from the attitude, Hz: (low, high)."""
        lo, hi = doppler_hz(self._speed_mps, self._wavelength_m, self._attitude_interval)
        return float(lo), float(hi)

    @property
    def centroid_hz(self) -> float:
        """Centre of the Doppler band the pre-filter keeps (as wide as :meth:`band_hz`'s),
        Hz: the centroid of the segment's echoes once measured, else the middle of the
        attitude's band."""
        squint = self._echo_squint_rad
        if squint is None:
            return float(np.mean(self.band_hz()))
        shift = squint - self._attitude_squint_rad
        return float(
            np.mean(
                doppler_hz(self._speed_mps, self._wavelength_m, self._attitude_interval + shift)
            )
        )

    def interval_at(self, t_ns: IntArray) -> FloatArray:
        """Squint interval of the pulses imaged at ``t_ns`` (GPS ns), rad, (P, 2); the
        intervals before the one of the first of them are forgotten."""
        k = np.clip(np.searchsorted(self._changes_ns, t_ns, side="right") - 1, 0, None)
        first = int(k[0]) if k.size else 0
        self._changes_ns, self._intervals = self._changes_ns[first:], self._intervals[first:]
        out = self._intervals[k - first]
        if out.size:
            lo, hi = self._span
            self._span = (min(lo, float(out[:, 0].min())), max(hi, float(out[:, 1].max())))
        return out

    def measure(self, rc: ComplexArray, t_ns: IntArray, rate_hz: float) -> None:
        """Measure the Doppler centroid of compensated, range-compressed pulses at
        ``rate_hz`` (ACCC) for the block pointed last, its ambiguity resolved with the
        attitude's; the first call after :meth:`point` records it.

        The beam the pixels take for that block then also covers the beam about the
        centroid of the segment's echoes so far (their correlations summed over the
        blocks whose echoes correlate, :data:`MIN_COHERENCE`).
        """
        if self._pending is None or rc.shape[0] < 2:
            return
        p = self._pending
        corr = accc_correlation(rc)
        if accc_coherence(rc, corr) >= MIN_COHERENCE:
            self._correlation += corr
        elif self._echo_squint_rad is None and not echoes_stand_out(rc, MIN_STANDOUT):
            self._intervals[-1] = self._unwidened  # noise alone: nothing to widen for
        echo = correlation_centroid_hz(corr, rate_hz)
        if math.isfinite(echo):
            echo = resolve_ambiguity(echo, p.attitude_hz, rate_hz)
        self.centroids.append(replace(p, t_ns=int(t_ns[0]), echo_hz=echo))
        self._pending = None
        steady = correlation_centroid_hz(self._correlation, rate_hz)
        if math.isfinite(steady):
            steady = resolve_ambiguity(steady, p.attitude_hz, rate_hz)
            sine = float(squint_sine(steady, self._speed_mps, self._wavelength_m))
            if abs(sine) < 1.0:
                self._echo_squint_rad = math.asin(sine)
                shift = self._echo_squint_rad - self._attitude_squint_rad
                lo, hi = self._intervals[-1]
                self._intervals[-1] = (min(lo, lo + shift), max(hi, hi + shift))

    def take_centroids(self) -> list[DopplerCentroid]:
        """The centroids recorded since the last call."""
        out, self.centroids = self.centroids, []
        return out


def segment_limits(cfg: Config, v0_mps: float) -> SegmentLimits:
    """Segmentation tolerances of the configuration for a platform at ``v0_mps``.

    A turn is a change of the aperture-averaged heading by more than the azimuth
    beamwidth over one synthetic aperture (``center_slant_range_m`` × beamwidth / v0,
    never shorter than an autofocus subaperture): a coordinated turn (about 12°/s) crosses
    it within a second, while turbulence, which the compensation and the attitude-steered
    beam absorb, stays below it (the real ArduPilot flight of the independent end-to-end
    check swings the aperture-averaged track by up to 1.35° against a 1.91° beam over 12 s
    of straight flight; half the beam flagged straight flight there as a turn and cut the
    apertures of the targets imaged then). Segments overlap at a deviation cut by
    the imaged beam's half footprint at far range over v0, plus 10 % (speed wander).
    """
    beam = math.radians(cfg.imaging.azimuth_beamwidth_deg)
    aperture_s = cfg.geometry.center_slant_range_m * beam / v0_mps
    return SegmentLimits(
        deviation_m=cfg.mocomp.segment_tolerance_m,
        turn_rad=beam,
        window_s=max(aperture_s, cfg.autofocus.subaperture_s),
        overlap_s=1.1 * tile_layout(cfg).half_footprint_m / v0_mps,
    )


def nan_motion(t_ns: IntArray) -> MocompSolution:
    """Motion rows of pulses that were not compensated (turns, pulses without navigation):
    NaN, no shift."""
    n = t_ns.shape[0]
    nan = np.full(n, math.nan)
    return MocompSolution(
        t_ns=np.asarray(t_ns, dtype=np.int64),
        disp_yz_m=np.full((n, 2), math.nan),
        d_los_m=nan,
        phase_rad=nan.copy(),
        range_shift_m=np.zeros(n),
    )


def _join(parts: list[MocompSolution]) -> MocompSolution:
    """One solution of consecutive pulses from several."""
    return MocompSolution(
        *(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(MocompSolution))
    )


class Focuser:
    """Range compression, INS compensation, autofocus, azimuth pre-filter, tiled backprojection.

    Parameters
    ----------
    cfg : Config
        Daemon configuration (radar, geometry, mocomp, autofocus, imaging).
    t0_ns : int
        GPS time of the first pulse: the first reference track starts there, ns.
    velocity_ned : ndarray, shape (3,)
        Mean antenna velocity of the flight from the start, NED, m/s: fixes the first
        track's heading (the image grid's along-track axis) and speed v0.
    sink : SinkFactory, optional
        Hand every segment's pulses ready for backprojection to a sink made by this
        instead of imaging them (no tiles come out; see :class:`TileSink`).
    quat : ndarray, shape (P, 4), optional
        Attitude (scalar-first, body to NED) of the first pulses: points the first
        segment's beam (its pre-filter band); broadside to the track when omitted.
    """

    def __init__(
        self,
        cfg: Config,
        t0_ns: int,
        velocity_ned: FloatArray,
        sink: SinkFactory | None = None,
        quat: FloatArray | None = None,
    ) -> None:
        self.cfg = cfg
        self._sink = sink
        self.radar = cfg.radar.params()
        self.range_m = rangecomp.range_axis_m(self.radar)
        self.window = None if cfg.imaging.window == "none" else cfg.imaging.window
        look_side = cfg.geometry.look_side
        track = ReferenceTrack.from_velocity(
            np.zeros(3), np.asarray(velocity_ned, dtype=np.float64), t0_ns, look_side
        )
        self.segmenter = (
            Segmenter(segment_limits(cfg, track.v0_mps), track, look_side)
            if cfg.mocomp.segments
            else None
        )
        self.segment: _Segment | None = _Segment(cfg, self.radar, track, sink, quat=quat)
        self._done = self.segment
        """The segment closed last (what :attr:`track` and :attr:`autofocus` show after it)."""
        self.segments = 1
        """Segments started so far."""
        self._tails: list[tuple[_Segment, int]] = []
        """Segments before a deviation cut still taking pulses, oldest first, each with the
        time from which it takes none (GPS ns)."""
        self._recent: list[tuple[ComplexArray, IntArray, FloatArray, FloatArray]] = []
        """Pulses (as pushed), times (GPS ns), velocities (NED, m/s) and attitudes the
        current segment took within the overlap (what a segment starting at a deviation cut
        takes first)."""
        im = cfg.imaging
        self.live = (
            LiveLevel(im.live_budget, im.live_window_s, im.live_min_level)
            if im.method in ("rda", "pfa") and im.live_degrade
            else None
        )
        """The degraded level of the live image, and whether its range-Doppler tiles are
        prompt (:mod:`sarmoco.daemon.livelevel`); None: tiles always at the configured
        pixels and swath, in blocks."""

    @property
    def track(self) -> ReferenceTrack:
        """Reference track of the current (or last) segment."""
        return self._last.track

    @property
    def autofocus(self) -> SlidingSubapertureAutofocus | None:
        """Autofocus engine of the current (or last) segment."""
        return self._last.autofocus

    @property
    def prefilter(self) -> AzimuthPrefilter | None:
        """Azimuth pre-filter of the current (or last) segment."""
        return self._last.prefilter

    def push(
        self,
        raw: ComplexArray,
        t_ns: IntArray,
        vel_ned: FloatArray,
        known: BoolArray | None = None,
        quat: FloatArray | None = None,
        after_skip: BoolArray | None = None,
    ) -> FocusOutput:
        """Process one block of aligned raw pulses.

        Parameters
        ----------
        raw : ndarray of complex, shape (P, S)
            Raw echoes (ADC counts).
        t_ns : ndarray of int64, shape (P,)
            Pulse times, GPS ns, increasing across calls.
        vel_ned : ndarray, shape (P, 3)
            Antenna phase centre velocity at the pulses (the aligner adds the lever
            arm's rate to the IMU velocity), NED, m/s.
        known : ndarray of bool, shape (P,), optional
            Pulses with navigation (false: zeroed echoes with a placeholder velocity
            across a navigation gap, which never sets a segment's track); all when omitted.
        quat : ndarray, shape (P, 4), optional
            Attitude at the pulses (scalar-first, body to NED): points the beam (its mean
            over the block); the beam keeps its pointing when omitted.
        after_skip : ndarray of bool, shape (P,), optional
            Pulses that follow recorded pulses the caller skipped (a live focuser fallen
            behind): the segment goes on across the hole, with its track, D_los and tile
            imager (:mod:`sarmoco.processing.segments`); none when omitted.
        """
        start = time.perf_counter()
        out = self._push(raw, t_ns, vel_ned, known, quat, after_skip)
        if self.live is not None and t_ns.shape[0]:
            # the data seconds of the pulses pushed: a hole the caller skipped (focusing
            # behind) or a silence of the radar is no time spent focusing
            data_s = t_ns.shape[0] / self.radar.prf_hz
            level = self.live.update(data_s, time.perf_counter() - start)
            for seg in (self.segment, *(tail for tail, _ in self._tails)):
                if seg is not None and isinstance(seg.tiles, LIVE_IMAGERS):
                    seg.tiles.level = level
                if seg is not None and isinstance(seg.tiles, RdaTileImager):
                    seg.tiles.prompt = self.live.prompt
        return out

    def _push(
        self,
        raw: ComplexArray,
        t_ns: IntArray,
        vel_ned: FloatArray,
        known: BoolArray | None,
        quat: FloatArray | None,
        after_skip: BoolArray | None,
    ) -> FocusOutput:
        """:meth:`push` without the live level's accounting."""
        q = np.full((t_ns.shape[0], 4), np.nan) if quat is None else np.asarray(quat)
        # range compression here, or after the pre-filter (imaging.presum_first)
        rc = raw if self._last.presum_first else rangecomp.compress(self.radar, raw, self.window)
        n = t_ns.shape[0]
        out = FocusOutput(turn=np.zeros(n, dtype=bool))
        if self.segmenter is None:
            assert self.segment is not None
            out.motion, tiles = self.segment.push(rc, t_ns, vel_ned, q)
            self._emit(out, self.segment, tiles)
            return out
        plan = self.segmenter.plan(t_ns, vel_ned, known, after_skip, body_heading_rad(q))
        out.turn = plan.turn
        begun = zip(plan.tracks, plan.cut_x_m, plan.offset_m, strict=True)
        new = dict(zip(plan.starts.tolist(), begun, strict=True))
        cuts = np.flatnonzero(np.diff(plan.turn)) + 1
        bounds = sorted({0, n, *cuts.tolist(), *new})
        motion: list[MocompSolution] = []
        for a, b in itertools.pairwise(bounds):
            if a in new:
                track, cut_x, offset = new[a]
                if math.isnan(cut_x):
                    self._close(out)
                    self.segment = _Segment(self.cfg, self.radar, track, self._sink, quat=q[a:b])
                else:
                    self._hand_over(out, track, float(cut_x), offset, int(t_ns[a]), q[a:b])
                self.segments += 1
            if plan.turn[a]:
                self._close(out)
                motion.append(nan_motion(t_ns[a:b]))
                continue
            assert self.segment is not None
            m, tiles = self.segment.push(rc[a:b], t_ns[a:b], vel_ned[a:b], q[a:b])
            motion.append(m)
            self._emit(out, self.segment, tiles)
            self._run_on(out, rc[a:b], t_ns[a:b], vel_ned[a:b], q[a:b])
        out.motion = _join(motion) if motion else nan_motion(t_ns)
        return out

    def _hand_over(
        self,
        out: FocusOutput,
        track: ReferenceTrack,
        cut_x: float,
        offset: FloatArray,
        t_cut: int,
        quat: FloatArray,
    ) -> None:
        """Start the segment of a deviation cut at ``t_cut`` (GPS ns) that overlaps the
        current one (see the module docstring); ``cut_x``: the cut's x on ``track``, m;
        ``offset``: the APC's offset from it at its first pulse, imaging frame, m;
        ``quat``: the attitude of the pulses from the cut (body to NED)."""
        old = self.segment
        assert old is not None and self.segmenter is not None
        # the cut line on the ground follows the beam centre at the cut: x - k y < c in the
        # new frame (x = cut_x + rho tan(psi), rho ~ rho_c + (y - y_c) y_c / rho_c)
        layout, tan_psi = old.tile_layout, math.tan(old.beam.scene_squint_rad)
        y_c, height = layout.ground_range_m, layout.height_m
        rho_c = math.hypot(y_c, height)
        k, c = tan_psi * y_c / rho_c, cut_x + tan_psi * height**2 / rho_c
        # the old frame's pixels p before it: w · (p_ned - origin) < c, w = x_hat - k y_hat
        w, before = track.x_hat - k * track.y_hat, old.track
        shift = float(w @ (before.origin_ned - track.origin_ned))
        old.keep(float(before.x_hat @ w), float(before.y_hat @ w), c - shift)
        self._tails.append((old, t_cut + self.segmenter.limits.overlap_ns))
        self.segment = _Segment(self.cfg, self.radar, track, self._sink, offset, quat)
        self.segment.keep(-1.0, k, -c)
        recent, self._recent = self._recent, []
        for pulses, t, vel, q in recent:
            rows = t >= track.t0_ns
            if rows.any():
                _, tiles = self.segment.push(pulses[rows], t[rows], vel[rows], q[rows])
                self._emit(out, self.segment, tiles)
                self._recent.append((pulses[rows], t[rows], vel[rows], q[rows]))

    def _run_on(
        self,
        out: FocusOutput,
        pulses: ComplexArray,
        t: IntArray,
        vel: FloatArray,
        quat: FloatArray,
    ) -> None:
        """Give pulses the current segment took to the segments before deviation cuts that
        still take them (ending those past their time), and keep them for the next cut."""
        for old, until_ns in self._tails:
            rows = t < until_ns
            if rows.any():
                pushed = old.push(pulses[rows], t[rows], vel[rows], quat[rows])
                self._emit(out, old, pushed[1])
        while self._tails and t[-1] >= self._tails[0][1]:
            self._end_tail(out)
        assert self.segmenter is not None
        overlap_ns = self.segmenter.limits.overlap_ns
        self._recent = [p for p in self._recent if p[1][-1] >= t[-1] - overlap_ns]
        if overlap_ns > 0:
            self._recent.append((pulses, t, vel, quat))

    def _emit(self, out: FocusOutput, segment: _Segment, tiles: list[Tile]) -> None:
        """Hand out a segment's finished tiles, or hold them while an older one runs on;
        hand out its Doppler centroids."""
        out.doppler += segment.beam.take_centroids()
        oldest = self._tails[0][0] if self._tails else segment
        if segment is oldest:
            out.add_tiles(tiles, segment.track)
        else:
            segment.held += tiles

    def _end_tail(self, out: FocusOutput) -> None:
        """End the oldest segment still running past its cut; release the next one's tiles."""
        old, _ = self._tails.pop(0)
        out.add_tiles(old.finish(), old.track)
        out.doppler += old.beam.take_centroids()
        after = self._tails[0][0] if self._tails else self.segment
        if after is not None:
            out.add_tiles(after.held, after.track)
            after.held = []

    def finish(self) -> FocusOutput:
        """Release what autofocus and the pre-filter still hold; close every tile (end of run)."""
        out = FocusOutput()
        self._close(out)
        return out

    def _close(self, out: FocusOutput) -> None:
        """End the segments still running past a cut, then the current one (if one is
        open): their last tiles go into ``out``; forget the pulses kept for a cut."""
        while self._tails:
            self._end_tail(out)
        self._recent = []
        if self.segment is not None:
            out.add_tiles(self.segment.finish(), self.segment.track)
            out.doppler += self.segment.beam.take_centroids()
            self._done = self.segment
            self.segment = None

    @property
    def _last(self) -> _Segment:
        return self.segment if self.segment is not None else self._done
