"""The streaming focusing chain of the daemon, configured from :class:`Config`.

Per block of aligned pulses: range compression → INS-only compensation
(D_los, METHODS §2) → sliding-subaperture autofocus (METHODS §3, optional) →
azimuth pre-filter (low-pass and decimate in slow time to the Doppler band of
the culled beam, optional) → backprojection onto ground tiles. Every stage is a
processing object with its own carried state, so a live run and a replay of the
same pulses give the same products. The reference track is fixed from the INS
velocity of the first block (straight line at the mean horizontal velocity,
METHODS §1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sarmoco.daemon.config import Config
from sarmoco.processing import rangecomp
from sarmoco.processing.autofocus import (
    AutofocusConfig,
    AutofocusGeometry,
    SlidingSubapertureAutofocus,
)
from sarmoco.processing.geometry import ReferenceTrack, vector_to_imaging
from sarmoco.processing.imaging.presum import AzimuthPrefilter, fill_slots, slot_steps
from sarmoco.processing.imaging.tiles import Tile, TileImager, TileLayout
from sarmoco.processing.mocomp import (
    InsMotionCompensator,
    LosGeometry,
    LosState,
    MocompSolution,
    integrate_los,
)
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray, RadarParams


def radar_params(cfg: Config) -> RadarParams:
    """The :class:`RadarParams` of the configured radar."""
    r = cfg.radar
    return RadarParams(
        carrier_hz=r.carrier_hz,
        bandwidth_hz=r.bandwidth_hz,
        pulse_width_s=r.pulse_width_s,
        sample_rate_hz=r.sample_rate_hz,
        prf_hz=r.prf_hz,
        n_samples=r.n_samples,
        range_gate_delay_s=r.range_gate_delay_s,
        receive=r.receive,
        chirp_direction=r.chirp_direction,
        iq_conjugate=r.iq_conjugate,
    )


@dataclass
class FocusOutput:
    """What one step of the chain produced.

    Attributes
    ----------
    motion : MocompSolution or None
        INS motion solution of the pulses pushed (None from :meth:`Focuser.finish`).
    tiles : list of Tile
        Image tiles finished in this step.
    """

    motion: MocompSolution | None = None
    tiles: list[Tile] = field(default_factory=list)


class Focuser:
    """Range compression, INS compensation, autofocus, azimuth pre-filter, tiled backprojection.

    Parameters
    ----------
    cfg : Config
        Daemon configuration (radar, geometry, mocomp, autofocus, imaging).
    t0_ns : int
        GPS time of the first pulse: the reference track starts there, ns.
    velocity_ned : ndarray, shape (3,)
        Mean INS velocity at the start, NED, m/s: fixes the track heading and speed v0.
    """

    def __init__(self, cfg: Config, t0_ns: int, velocity_ned: FloatArray) -> None:
        self.cfg = cfg
        self.radar = radar_params(cfg)
        self.range_m = rangecomp.range_axis_m(self.radar)
        self.window = None if cfg.imaging.window == "none" else cfg.imaging.window
        geo = cfg.geometry
        self.track = ReferenceTrack.from_velocity(
            np.zeros(3), np.asarray(velocity_ned, dtype=np.float64), t0_ns, geo.look_side
        )
        los = LosGeometry.build(
            self.radar,
            self.range_m,
            geo.height_m,
            geo.center_slant_range_m,
            self.track.v0_mps,
            order=cfg.mocomp.order,
            envelope_fraction=cfg.mocomp.envelope_fraction,
        )
        self.mocomp = InsMotionCompensator(self.track, los)
        self._along: LosState | None = (
            LosState(last_vel_yz=np.zeros(1), disp_yz_m=np.zeros(1))
            if cfg.mocomp.along_track
            else None
        )
        self._last_tau_ns: int | None = None
        self._slot_ns: int | None = None
        """Time of the last pulse given to the autofocus, GPS ns."""
        self._period_ns = round(1e9 / self.radar.prf_hz)
        self._max_fill_slots = max(1, round(cfg.autofocus.subaperture_s * self.radar.prf_hz))
        af = cfg.autofocus
        self.autofocus = (
            SlidingSubapertureAutofocus(
                AutofocusGeometry(
                    self.radar.wavelength_m,
                    self.track.v0_mps,
                    geo.height_m,
                    geo.center_slant_range_m,
                ),
                self.range_m,
                AutofocusConfig(
                    subaperture_s=af.subaperture_s,
                    hop_s=af.hop_s,
                    n_lines=af.n_lines,
                    estimator="map_drift" if af.estimator == "map-drift" else "contrast",
                    envelope_step=af.envelope_step,
                    range_order=af.range_order,
                    pin_window_s=af.pin_window_s,
                    phase_passes=af.phase_passes,
                ),
            )
            if af.enabled
            else None
        )
        ground_range = math.sqrt(max(geo.center_slant_range_m**2 - geo.height_m**2, 0.0))
        im = cfg.imaging
        beam_rad = math.radians(im.azimuth_beamwidth_deg + 2.0 * im.squint_tolerance_deg)
        self.imager = TileImager(
            TileLayout(
                height_m=geo.height_m,
                ground_range_m=ground_range,
                swath_m=im.swath_m,
                tile_length_m=im.tile_length_m,
                pixel_m=im.pixel_m,
                beamwidth_rad=beam_rad,
            ),
            self.range_m,
            self.radar.wavelength_m,
        )
        doppler_hz = 2.0 * self.track.v0_mps * math.sin(beam_rad / 2.0) / self.radar.wavelength_m
        self.prefilter = (
            AzimuthPrefilter(self.radar.prf_hz, doppler_hz, im.prefilter_oversampling)
            if im.prefilter and doppler_hz > 0
            else None
        )

    def push(self, raw: ComplexArray, t_ns: IntArray, vel_ned: FloatArray) -> FocusOutput:
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
        """
        rc = rangecomp.compress(self.radar, raw, self.window)
        rc, motion = self.mocomp.compensate(rc, t_ns, vel_ned)
        out = FocusOutput(motion=motion)
        t_ns = self._along_track_time(t_ns, vel_ned)
        if self.autofocus is None:
            out.tiles = self._image(rc, t_ns)
            return out
        rc, t_ns = self._keep_slots(rc, t_ns)
        focused, corr = self.autofocus.push(rc, t_ns)
        out.tiles = self._image(focused, corr.t_ns)
        return out

    def _keep_slots(self, rc: ComplexArray, t_ns: IntArray) -> tuple[ComplexArray, IntArray]:
        """Zero rows in the PRF slots of missing pulses, for the autofocus.

        The autofocus estimates Doppler rates with FFTs over the pulses of a subaperture,
        taken as uniformly spaced: a lost datagram that left no hole would shift every
        later pulse of the subaperture by a PRI (2 % loss: -13.1 -> -10.4..-11.1 dB
        azimuth PSLR on ku-vehicle x0.1). Gaps up to a subaperture are filled; a longer
        one leaves no subaperture to estimate across anyway.
        """
        if t_ns.size == 0:
            return rc, t_ns
        last = self._slot_ns if self._slot_ns is not None else int(t_ns[0]) - self._period_ns
        steps = slot_steps(t_ns, last, self._period_ns)
        self._slot_ns = int(t_ns[-1])
        steps[(steps < 1) | (steps > self._max_fill_slots)] = 1
        return fill_slots(rc, t_ns, steps, last)

    def finish(self) -> FocusOutput:
        """Release what autofocus and the pre-filter still hold; close every tile (end of run)."""
        out = FocusOutput()
        if self.autofocus is not None:
            focused, corr = self.autofocus.flush()
            out.tiles = self._image(focused, corr.t_ns)
        if self.prefilter is not None:
            out.tiles += self._backproject(*self.prefilter.flush())
        out.tiles += self.imager.close()
        return out

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
        if self.prefilter is not None:
            rc, t_ns = self.prefilter.push(rc, t_ns)
        return self._backproject(rc, t_ns)

    def _backproject(self, rc: ComplexArray, t_ns: IntArray) -> list[Tile]:
        if rc.shape[0] == 0:
            return []
        return self.imager.add(rc, t_ns, self.track.position_imaging(t_ns))
