"""3-D imaging of a MIMO downward-looking array and its DEM product (docs/methods.md §4).

Chain, on echoes [pulse, channel, fast time] with per-pulse INS position and attitude:

1. range compression of every channel (:func:`sarmoco.processing.rangecomp.compress`);
2. near-field and EPC correction per channel c and range bin r: the pair's two-way path is
   ``(R_tx + R_rx)/2 = R_0 - y_c sin θ + (y_c² + b_c²/4) cos² θ / (2 R_0)`` to second order
   (y_c: EPC across the wing, b_c: baseline, θ: look angle off nadir). The quadratic term,
   whose ``b_c² cos²θ / (8 R_0)`` part is the EPC's bistatic correction
   (:func:`~sarmoco.processing.array.geometry.bistatic_residual_m`), is removed with
   ``cos θ = min(1, depth / r)`` for a reference ground at ``ground_height_m``; what stays is
   a uniform virtual array phased from infinity;
3. attitude and position errors: ΔR1 and ΔR2 on sub-blocks (:mod:`.roll`);
4. along-track (azimuth) compression per range bin, range-Doppler:
   ``exp(+j r (sqrt(4k² - k_x²) - 2k))`` over the Doppler band ``|k_x| <= 2k λ/D``; range
   migration is left (at most ``r (1/sqrt(1 - (λ/D)²) - 1)`` = 0.12 m at 250 m, λ/D = 1/32,
   under an eighth of the 1 m range cell);
5. cross-track beamforming in the range-frequency domain, steering
   ``exp(-j k_r y_c sin θ)`` per frequency (k_r = 4π f / c), which also aligns the range
   envelopes across the array (up to 0.55 m apart at 20° for a 3.2 m array);
6. per along-track position and angle, the range-profile intensities of ``looks`` neighbouring
   pulses are averaged and the surface range is the intensity centroid of the upsampled
   profile over ``centroid_cells`` resolution cells about its peak (intensity above
   ``centroid_floor`` of the peak): on a slope the beam's footprint spreads over several
   range cells and speckle moves the peak within it, while the centroid stays near the
   footprint's centre (paper's terrain, full array, steepest strip, at b3182a8: std 0.25 m
   with the parabolic peak, 0.175 m with a 4-cell centroid). Where the surface climbs along
   track faster than ``slope_switch`` the single-look centroid is taken (a strip across
   along-track slopes: 0.402 m with 3 looks everywhere, 0.261 m with the switch and a 6-cell
   centroid); (r, θ) maps to ``y = r sin θ``,
   ``z = r cos θ`` in the imaging frame, height ``h = -(D_origin + z)``; the heights are
   interpolated per pulse onto a regular cross-track grid, NaN where the profile's peak is
   below the echo threshold, in the receive window's last pulse length (cut echoes) or more
   than ``outlier_cells`` range cells from the median height of its 7 neighbouring beams.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft
from scipy.ndimage import median_filter

from sarmoco.errors import ProcessingError
from sarmoco.processing.array.geometry import ArrayLayout
from sarmoco.processing.array.roll import compensate, epc_deviation, mean_roll_sine
from sarmoco.processing.geometry import ReferenceTrack, fit_reference_track
from sarmoco.processing.rangecomp import compress, range_axis_m
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, IntArray, RadarParams


@dataclass(frozen=True)
class ArraySystem:
    """The radar, its array and its antenna beams.

    Parameters
    ----------
    radar : RadarParams
        Waveform and receive window shared by every channel (``receive = "matched"``).
    layout : ArrayLayout
        Body-frame transmitters and receivers; their EPCs must form a uniform virtual array.
    antenna_length_m : float
        Along-track element length D, m (Doppler band |k_x| <= 2k λ/D).
    max_look_rad : float
        Largest look angle off nadir across track, rad (the swath the elements see).
    """

    radar: RadarParams
    layout: ArrayLayout
    antenna_length_m: float
    max_look_rad: float

    def __post_init__(self) -> None:
        if not self.antenna_length_m > 0.0:
            raise ProcessingError(
                f"ArraySystem.antenna_length_m: {self.antenna_length_m!r} is not > 0"
            )
        if not 0.0 < self.max_look_rad < math.pi / 2.0:
            raise ProcessingError(
                f"ArraySystem.max_look_rad: {self.max_look_rad!r} not in (0, π/2)"
            )
        if self.radar.receive != "matched":
            raise ProcessingError("ArraySystem.radar.receive: the array imager needs 'matched'")

    @property
    def height_resolution_m(self) -> float:
        """The paper's height (slant-range) resolution c / 2B, m."""
        return self.radar.range_resolution_m


@dataclass(frozen=True)
class Array3dOptions:
    """How the array imager runs.

    Parameters
    ----------
    compensate_attitude : bool
        Use the INS attitude (roll, pitch, yaw) for the element positions. False images as
        if the wing were level (the linear errors are still removed): "before compensation".
    blocks : (int, int)
        ΔR2 sub-blocks along k_x and k_y.
    grid_spacing_m : float
        Cross-track spacing of the DEM grid, m.
    range_upsample : int
        Zero-padding factor of the range profiles before the peak search.
    angle_oversample : float
        Beams per beamwidth λ / (2 L) of the virtual array (length L).
    cross_window : str or None
        Taper across the virtual array (scipy window name); None: uniform.
    looks : int
        Along-track pulses whose range-profile intensities are averaged (odd, >= 1) before
        the peak search: fewer speckle errors, coarser along-track resolution.
    centroid_cells : float
        Width of the window around each profile's peak, in range resolution cells, over which
        the surface range is the intensity centroid; 0: the parabolic peak instead.
    centroid_floor : float
        Intensity below this fraction of the peak is left out of the centroid.
    threshold_db : float
        A profile whose peak is this far below the 90th percentile of all peaks is "no echo".
    slope_switch : float
        Where the looked surface climbs along track faster than this (m per m), the single
        look's range is used instead: averaging neighbouring pulses mixes their heights.
        0: always the looked range.
    outlier_cells : float
        A beam's height more than this many range resolution cells from the median of its 7
        neighbouring beams is dropped as a sidelobe or noise peak.
    ground_height_m : float
        Reference ground height (up) for the near-field correction's look angle, m.
    """

    compensate_attitude: bool = True
    blocks: tuple[int, int] = (1, 8)
    grid_spacing_m: float = 0.5
    range_upsample: int = 8
    angle_oversample: float = 2.0
    cross_window: str | None = None
    looks: int = 3
    centroid_cells: float = 6.0
    centroid_floor: float = 0.1
    threshold_db: float = -15.0
    outlier_cells: float = 3.0
    slope_switch: float = 1.0
    ground_height_m: float = 0.0

    def __post_init__(self) -> None:
        if len(self.blocks) != 2 or min(self.blocks) < 1:
            raise ProcessingError(f"Array3dOptions.blocks: {self.blocks!r} is not two counts >= 1")
        object.__setattr__(self, "blocks", (int(self.blocks[0]), int(self.blocks[1])))
        if not self.grid_spacing_m > 0.0:
            raise ProcessingError(f"Array3dOptions.grid_spacing_m: {self.grid_spacing_m!r} <= 0")
        if self.looks < 1 or self.looks % 2 == 0:
            raise ProcessingError(f"Array3dOptions.looks: {self.looks!r} is not an odd count >= 1")
        if self.range_upsample < 1 or not self.angle_oversample >= 1.0:
            raise ProcessingError(
                "Array3dOptions: range_upsample and angle_oversample must be >= 1"
            )


@dataclass(frozen=True)
class DemProduct:
    """An imaged DEM on a regular grid of the imaging frame.

    Parameters
    ----------
    height_m : ndarray of float64, shape (n_x, n_y)
        Height above the NED origin (-down), m; NaN where no echo.
    x_m : ndarray of float64, shape (n_x,)
        Along-track coordinate of each row (the pulses' reference-track positions), m.
    y_m : ndarray of float64, shape (n_y,)
        Cross-track coordinate of each column (right of track), m.
    track : ReferenceTrack
        The imaging frame (origin, axes) in NED.
    compensated : bool
        Whether the attitude was used (False: the "before compensation" image).
    blocks : (int, int)
        The ΔR2 sub-blocks used.
    """

    height_m: FloatArray
    x_m: FloatArray
    y_m: FloatArray
    track: ReferenceTrack
    compensated: bool
    blocks: tuple[int, int]

    def points_ned(self) -> FloatArray:
        """NED north and east of every cell, (n_x, n_y, 2), m."""
        xx, yy = np.meshgrid(self.x_m, self.y_m, indexing="ij")
        ne = (
            self.track.origin_ned[None, None, :2]
            + xx[..., None] * self.track.x_hat[None, None, :2]
            + yy[..., None] * self.track.y_hat[None, None, :2]
        )
        return np.asarray(ne, dtype=np.float64)


def _validate(
    echoes: ComplexArray, t_ns: IntArray, pos_ned: FloatArray, quat: FloatArray, system: ArraySystem
) -> None:
    shape = np.shape(echoes)
    want = (system.layout.n_channels, system.radar.n_samples)
    if len(shape) != 3 or shape[1:] != want:
        raise ProcessingError(f"form_dem: echoes shape {shape} is not (P, {want[0]}, {want[1]})")
    n_p = shape[0]
    if np.shape(t_ns) != (n_p,) or np.shape(pos_ned) != (n_p, 3) or np.shape(quat) != (n_p, 4):
        raise ProcessingError(
            f"form_dem: t_ns{np.shape(t_ns)} pos_ned{np.shape(pos_ned)} quat{np.shape(quat)} "
            f"are not ({n_p},), ({n_p}, 3), ({n_p}, 4)"
        )
    if n_p < 2 or np.any(np.diff(np.asarray(t_ns)) <= 0):
        raise ProcessingError("form_dem: pulse times t_ns must increase (at least two pulses)")


def _near_field(data: ComplexArray, system: ArraySystem, r: FloatArray, depth_m: float) -> None:
    """Step 2 of the module docstring, in place on range-compressed [P, C, S] data."""
    y = system.layout.epc_body_m[:, 1]
    b = system.layout.baseline_m
    cos2 = np.minimum(1.0, depth_m / r) ** 2
    k = 2.0 * math.pi / system.radar.wavelength_m
    phase = 2.0 * k * (y[:, None] ** 2 + b[:, None] ** 2 / 4.0) * cos2[None, :] / (2.0 * r[None, :])
    data *= np.exp(1j * phase).astype(np.complex64)[None, :, :]


def _azimuth_compress(data: ComplexArray, system: ArraySystem, r: FloatArray, dx: float) -> None:
    """Step 4 of the module docstring, in place on range-compressed [P, C, S] data."""
    n_p = data.shape[0]
    lam = system.radar.wavelength_m
    k = 2.0 * math.pi / lam
    aperture = 2.0 * float(r.max()) * lam / system.antenna_length_m
    n_fft = scipy.fft.next_fast_len(n_p + math.ceil(aperture / dx) + 1)
    kx = 2.0 * math.pi * scipy.fft.fftfreq(n_fft, dx)
    band = np.abs(kx) <= 2.0 * k * lam / system.antenna_length_m
    kz = np.sqrt(np.clip(4.0 * k * k - kx * kx, 0.0, None)) - 2.0 * k
    filt = np.where(band[:, None], np.exp(1j * kz[:, None] * r[None, :]), 0.0).astype(np.complex64)
    spec = scipy.fft.fft(data, n_fft, axis=0, workers=-1)
    spec *= filt[:, None, :]
    data[...] = scipy.fft.ifft(spec, axis=0, workers=-1)[:n_p]


def _beam_sines(system: ArraySystem, centre: float, oversample: float) -> FloatArray:
    """Sines of the beams, in steps of the beamwidth / oversample.

    The fan is ``centre ± (sin(max_look) - beamwidth)``: a beam straddling the edge of the
    illuminated swath sees half a footprint and its centroid is pulled inward (up to 2.5 m
    on flat ground at 200 m with 2 × 20 elements).
    """
    _, d = system.layout.virtual_array()
    length = d * system.layout.n_channels
    width = system.radar.wavelength_m / (2.0 * length)
    step = width / oversample
    half = math.sin(system.max_look_rad) - width
    n = math.floor(half / step)
    return np.asarray(centre + step * np.arange(-n, n + 1), dtype=np.float64)


def _surface_ranges(
    data_t: ComplexArray,
    system: ArraySystem,
    sines: FloatArray,
    opt: Array3dOptions,
    chunk: int = 32,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Beamform (step 5), average ``opt.looks`` neighbouring pulses' intensity profiles and
    find each profile's peak (step 6).

    Returns the surface position (fractional range bins of the window) with the looks, the
    same from single pulses, and the looked peak power, each (P, n_beams).
    """
    n_p, n_c, n_data = data_t.shape
    radar = system.radar
    y = system.layout.epc_body_m[:, 1]
    # zero guard at the window's end: the steering delays (up to |y| sin θ) and the profile
    # interpolation are circular in range, an echo at the window's end must not wrap to its start
    bin_m = C_MPS / (2.0 * radar.sample_rate_hz)
    n_s = scipy.fft.next_fast_len(n_data + math.ceil(float(np.max(np.abs(y))) / bin_m) + 8)
    kr = 4.0 * math.pi * (radar.carrier_hz + scipy.fft.fftfreq(n_s, 1.0 / radar.sample_rate_hz))
    kr /= C_MPS
    window = opt.cross_window
    w = np.ones(n_c)
    if window is not None:  # scipy.signal only then: its import is most of a daemon's start
        from scipy.signal import get_window

        w = get_window(window, n_c + 2, fftbins=False)[1:-1]
    order = np.argsort(y)
    weights = np.empty(n_c)
    weights[order] = w
    steer = (
        weights[None, :, None]
        * np.exp(-1j * kr[:, None, None] * y[None, :, None] * sines[None, None, :])
    ).astype(np.complex64)  # (F, C, B)
    up = opt.range_upsample
    n_up = n_s * up
    half = n_s // 2
    halo = opt.looks // 2
    res_bins = system.radar.range_resolution_m / (C_MPS / (2.0 * system.radar.sample_rate_hz))
    pos = np.empty((n_p, sines.size))
    power = np.empty((n_p, sines.size))
    single = pos if halo == 0 else np.empty((n_p, sines.size))
    for p0 in range(0, n_p, chunk):
        lo, hi = max(0, p0 - halo), min(n_p, p0 + chunk + halo)
        blk = scipy.fft.fft(data_t[lo:hi], n_s, axis=2, workers=-1)  # (Pc, C, F)
        beams = np.matmul(np.transpose(blk, (2, 0, 1)), steer)  # (F, Pc, B)
        padded = np.zeros((n_up, *beams.shape[1:]), dtype=np.complex64)
        padded[:half] = beams[:half]
        padded[n_up - (n_s - half) :] = beams[half:]
        prof = np.abs(scipy.fft.ifft(padded, axis=0, workers=-1)) ** 2  # (S U, Pc, B)
        keep = slice(p0 - lo, p0 - lo + min(chunk, n_p - p0))
        if halo:
            csum = np.concatenate([np.zeros_like(prof[:, :1]), np.cumsum(prof, axis=1)], axis=1)
            idx = np.arange(prof.shape[1])
            a_i = np.clip(idx - halo, 0, prof.shape[1])
            b_i = np.clip(idx + halo + 1, 0, prof.shape[1])
            looked = (csum[:, b_i] - csum[:, a_i]) / (b_i - a_i)[None, :, None]
            single[p0 : p0 + chunk] = _peak_bins(prof[:, keep], opt, up, res_bins)[0]
        else:
            looked = prof
        pos[p0 : p0 + chunk], power[p0 : p0 + chunk] = _peak_bins(
            looked[:, keep], opt, up, res_bins
        )
    return pos, single, power


def _peak_bins(
    prof: FloatArray, opt: Array3dOptions, up: int, res_bins: float
) -> tuple[FloatArray, FloatArray]:
    """Surface position (original range bins, fractional) and peak power of profiles
    (S U, P, B): the centroid of step 6, or the parabolic peak."""
    n_up = prof.shape[0]
    i = np.argmax(prof, axis=0)
    b = np.take_along_axis(prof, i[None], 0)[0]
    if opt.centroid_cells > 0.0:
        half_w = round(opt.centroid_cells * up * res_bins / 2.0)
        offs = np.arange(-half_w, half_w + 1)
        idx = np.clip(i[None] + offs[:, None, None], 0, n_up - 1)
        vals = np.take_along_axis(prof, idx, 0)
        vals = np.maximum(vals - opt.centroid_floor * b[None], 0.0)
        frac = np.sum(vals * offs[:, None, None], axis=0) / np.sum(vals, axis=0)
    else:
        a = np.take_along_axis(prof, np.clip(i - 1, 0, n_up - 1)[None], 0)[0]
        c = np.take_along_axis(prof, np.clip(i + 1, 0, n_up - 1)[None], 0)[0]
        den = a - 2.0 * b + c
        frac = np.where(den < 0.0, 0.5 * (a - c) / np.where(den < 0.0, den, -1.0), 0.0)
    return (i + frac) / up, b


def _plausible(bins: FloatArray, h: FloatArray, radar: RadarParams, tol_m: float) -> np.ndarray:
    """Beams whose surface range is usable (step 6's outlier rejection), (P, n_beams) bool.

    A peak in the last pulse length of the receive window is an echo cut by the window's end
    (or no echo), and a height farther than ``tol_m`` from the median of its 7 neighbouring
    beams is a sidelobe or noise peak, not the surface.
    """
    n_pulse = radar.pulse_width_s * radar.sample_rate_hz
    inside = (bins >= 1.0) & (bins <= radar.n_samples - n_pulse - 1.0)
    med = median_filter(h, size=(1, 7), mode="nearest")
    return np.asarray(inside & (np.abs(h - med) <= tol_m))


def _grid_heights(
    y: FloatArray, h: FloatArray, valid: np.ndarray, y_grid: FloatArray, max_gap: float
) -> FloatArray:
    out = np.full((y.shape[0], y_grid.size), np.nan)
    for p in range(y.shape[0]):
        v = valid[p]
        if np.count_nonzero(v) < 2:
            continue
        yy, hh = y[p, v], h[p, v]
        order = np.argsort(yy)
        yy, hh = yy[order], hh[order]
        row = np.interp(y_grid, yy, hh, left=np.nan, right=np.nan)
        gap_after = np.searchsorted(yy, y_grid).clip(1, yy.size - 1)
        gaps = yy[gap_after] - yy[gap_after - 1]
        row[gaps > max_gap] = np.nan
        out[p] = row
    return out


def _compensate_motion(
    data: ComplexArray,
    t: IntArray,
    pos: FloatArray,
    quat: FloatArray,
    system: ArraySystem,
    track: ReferenceTrack,
    dx: float,
    opt: Array3dOptions,
) -> tuple[ComplexArray, float]:
    """Range-compressed echoes (P, M N, S) compensated for the virtual elements' deviation
    from the reference track (wavenumber domain, ``opt.blocks`` sub-blocks), and the sine of
    the boresight's cross-track angle that the compensation centred the k_y band on.

    ``dx`` is the pulse spacing along track, m; ``quat`` the INS attitude (used only when
    ``opt.compensate_attitude``).
    """
    radar = system.radar
    n_p, _, n_s = data.shape
    y_epc, d = system.layout.virtual_array()
    kr = (
        4.0
        * math.pi
        * (radar.carrier_hz + scipy.fft.fftfreq(n_s, 1.0 / radar.sample_rate_hz))
        / C_MPS
    )
    level = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (n_p, 1))
    att = np.asarray(quat, dtype=np.float64) if opt.compensate_attitude else level
    dev = epc_deviation(t, pos, att, system.layout, track)
    # a roll α (right wing down) turns the elements' boresight to sin θ = -sin α (left): the
    # echo's k_y band and the beams are centred there
    boresight = -mean_roll_sine(dev, y_epc)
    k_c = 4.0 * math.pi / radar.wavelength_m
    spec = scipy.fft.fft(data, axis=2, workers=-1)
    compensate(spec, dev, np.argsort(y_epc), kr, dx, d, opt.blocks, ky_centre=k_c * boresight)
    return scipy.fft.ifft(spec, axis=2, workers=-1), boresight


def form_dem(
    echoes: ComplexArray,
    t_ns: IntArray,
    pos_ned: FloatArray,
    quat: FloatArray,
    system: ArraySystem,
    options: Array3dOptions | None = None,
) -> DemProduct:
    """Image a strip of array echoes in 3-D and return its DEM (module docstring).

    Parameters
    ----------
    echoes : ndarray of complex, shape (P, M N, S)
        Raw echoes [pulse, channel, fast time], channel c = m N + n (tx-major), S =
        ``system.radar.n_samples``. Pulses are assumed evenly spaced along track.
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns, increasing.
    pos_ned : ndarray of float64, shape (P, 3)
        INS reference-point (body origin) position at each pulse, NED, m.
    quat : ndarray of float64, shape (P, 4)
        INS attitude at each pulse, scalar-first body-to-NED quaternion.
    system : ArraySystem
        Radar, array layout, antenna beams.
    options : Array3dOptions, optional
        Processing choices (defaults: attitude compensated, 1 × 8 sub-blocks).

    Returns
    -------
    DemProduct
        Heights on (pulse along-track position, regular cross-track grid).
    """
    opt = Array3dOptions() if options is None else options
    _validate(echoes, t_ns, pos_ned, quat, system)
    t = np.asarray(t_ns, dtype=np.int64)
    pos = np.asarray(pos_ned, dtype=np.float64)
    n_p, n_c, n_s = np.shape(echoes)
    radar = system.radar
    track = fit_reference_track(t, pos)
    dx = track.v0_mps * float(np.median(np.diff(t))) * 1e-9

    data = compress(radar, np.asarray(echoes).reshape(n_p * n_c, n_s)).reshape(n_p, n_c, n_s)
    r = range_axis_m(radar)
    depth = -opt.ground_height_m - float(track.origin_ned[2])
    _near_field(data, system, r, depth)

    data, boresight = _compensate_motion(data, t, pos, quat, system, track, dx, opt)
    _azimuth_compress(data, system, r, dx)
    sines = _beam_sines(system, boresight, opt.angle_oversample)
    bins, bins_single, power = _surface_ranges(data, system, sines, opt)
    r0, dr = float(r[0]), float(r[1] - r[0])
    cos_t = np.sqrt(1.0 - sines**2)
    if opt.looks > 1 and opt.slope_switch > 0.0:
        # the looks average along track: where the surface climbs along track faster than
        # slope_switch (height over along-track distance, from the looked heights), one look
        slope = np.abs(np.gradient((r0 + bins * dr) * cos_t[None, :], dx, axis=0))
        bins = np.where(slope > opt.slope_switch, bins_single, bins)
    rng_m = r0 + bins * dr
    y_img = rng_m * sines[None, :]
    z_img = rng_m * cos_t[None, :]
    h = -(float(track.origin_ned[2]) + z_img)
    ref = np.percentile(power, 90.0)
    valid = power >= ref * 10.0 ** (opt.threshold_db / 10.0)
    valid &= _plausible(bins, h, radar, opt.outlier_cells * radar.range_resolution_m)
    span = float(np.max(np.abs(y_img[valid]))) if np.any(valid) else 1.0
    n_half = math.ceil(span / opt.grid_spacing_m)
    y_grid = opt.grid_spacing_m * np.arange(-n_half, n_half + 1, dtype=np.float64)
    beam_step = float(rng_m.mean()) * float(sines[1] - sines[0])
    height = _grid_heights(
        y_img, h, valid, y_grid, max_gap=3.0 * max(beam_step, opt.grid_spacing_m)
    )
    x_axis = track.position_imaging(t)[:, 0]
    return DemProduct(height, x_axis, y_grid, track, opt.compensate_attitude, opt.blocks)
