"""Configuration: one TOML file loaded into frozen, typed objects.

Every section is a frozen dataclass; every field carries its unit, its
documentation and its constraints in ``dataclasses.field`` metadata, so the
loader, the error messages and the key table of docs/configuration.md all come from one
place.
Errors name the key path, the bad value and what is allowed
(``radar.prf_hz: -3 is not > 0``); unknown keys are errors.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from sarmoco.errors import ConfigError, ProcessingError
from sarmoco.keys import key as _key
from sarmoco.processing.autofocus.settings import AutofocusConfig
from sarmoco.processing.geometry import look_angle
from sarmoco.processing.imaging.presum import PREFILTER_OVERSAMPLING
from sarmoco.processing.imaging.rda_tiles import LEVELS
from sarmoco.processing.imaging.tile_pga import TilePgaConfig
from sarmoco.processing.mocomp import DEFAULT_ENVELOPE_FRACTION
from sarmoco.processing.types import C_MPS, RadarParams
from sarmoco.store.schema import ECHO_COMPRESSION


@dataclass(frozen=True)
class RadarConfig(RadarParams):
    """Radar waveform, receiver and echo link.

    The waveform and receiver keys are the fields of the physics' own description,
    :class:`~sarmoco.processing.types.RadarParams` (their defaults, units and bounds are
    declared there); the daemon adds the link, the sample format, the channels and the
    mode.
    """

    link: str = _key(
        "udp://127.0.0.1:49152",
        "Where VITA 49.2 echo packets arrive: udp://HOST:PORT (listen), tcp://HOST:PORT "
        "(connect), or a .vrt file path for replay",
    )
    sample_format: Literal["int16", "float32"] = _key("int16", "I/Q sample type on the wire")
    channels: int = _key(
        1,
        "Receive channels: 1 in single mode; array.n_tx * array.n_rx in array mode (VITA "
        "stream IDs: array.stream_ids)",
        gt=0,
    )
    stream_id: int | None = _key(
        None,
        "VITA stream identifier (the digitiser's own 32-bit value) focused in single mode; "
        "signal packets of other streams are counted (radar driver's rejected) and skipped. "
        "Unset: the first signal stream that arrives (its ID is logged)",
        ge=0,
        le=0xFFFFFFFF,
    )
    mode: Literal["single", "array"] = _key(
        "single",
        "single: one channel, side-looking SAR focused into image tiles (stripmap or "
        "spotlight); array: MIMO downward-looking array, one stream ID per Tx/Rx "
        "pair, imaged in 3-D into a DEM (section array)",
    )

    def params(self) -> RadarParams:
        """The radar as processing takes it: the :class:`RadarParams` part of these keys."""
        return RadarParams(
            **{f.name: getattr(self, f.name) for f in dataclasses.fields(RadarParams)}
        )

    def slant_window_m(self) -> tuple[float, float]:
        """Slant ranges of the first and last range bin of the compressed pulses, m.

        The span of :func:`sarmoco.processing.rangecomp.range_axis_m`: matched filter
        ``c/2 (gate + i / f_s)``; dechirp ``c/2 (gate + f_i / K)`` over the beat frequencies
        ``f_i = (i - N/2) f_s / N``.

        Raises
        ------
        ConfigError
            Dechirp with a chirp rate ``bandwidth_hz / pulse_width_s`` that underflows to 0.
        """
        half_c = C_MPS / 2.0
        n, fs, gate = self.n_samples, self.sample_rate_hz, self.range_gate_delay_s
        if self.receive == "matched":
            return half_c * gate, half_c * (gate + (n - 1) / fs)
        k = self.bandwidth_hz / self.pulse_width_s
        if not k > 0:  # both keys are > 0, but their quotient can underflow
            raise ConfigError(
                f"radar.bandwidth_hz / radar.pulse_width_s: {self.bandwidth_hz!r} Hz / "
                f"{self.pulse_width_s!r} s is no chirp rate (underflows to 0)"
            )
        return (
            half_c * (gate - (n // 2) * fs / n / k),
            half_c * (gate + (n - 1 - n // 2) * fs / n / k),
        )


InsProtocol = Literal["mavlink", "sbg", "sbg-can"]
"""Every INS wire protocol the daemon speaks (opened by ``links.INS_OPENERS``)."""


@dataclass(frozen=True)
class InsConfig:
    """Navigation source (INS velocity and attitude)."""

    protocol: str = _key(
        "mavlink", "Wire protocol of the INS", choices=typing.get_args(InsProtocol)
    )
    link: str = _key(
        "udpin:127.0.0.1:14550",
        "MAVLink: a pymavlink connection string (udpin:, tcp:, /dev/tty..., .tlog, .bin); "
        "SBG: a serial device or binary log; SBG CAN: interface:channel (socketcan:can0, "
        "slcan:/dev/ttyACM0, socketcand:127.0.0.1:29536:can0, or a candump log)",
    )
    baudrate: int = _key(921600, "Serial baud rate (serial links only)", unit="bit/s", gt=0)
    rate_hz: float = _key(100.0, "Rate requested from the INS", unit="Hz", gt=0, le=1000)
    lever_arm_m: tuple[float, float, float] = _key(
        (0.0, 0.0, 0.0), "IMU to antenna phase centre, body frame (forward, right, down)", unit="m"
    )
    max_gap_s: float = _key(
        0.05,
        "Longest INS sample interval interpolated across unflagged; longer ones up to "
        "bridge_gap_s are bridged (flagged NAV_BRIDGED)",
        unit="s",
        gt=0,
    )
    latency_budget_s: float = _key(
        0.5,
        "How long a pulse waits for INS samples that bracket it before it is flagged",
        unit="s",
        gt=0,
    )
    bridge_gap_s: float = _key(
        0.4,
        "Longest INS silence bridged: pulses between samples further apart than max_gap_s "
        "but not than this get navigation interpolated across it, are focused and flagged "
        "NAV_BRIDGED; longer silences flag their pulses NAV_GAP (not focused). The LOS error "
        "of the bridge in 0.3 m rms turbulence: ~1 mm at 0.3 s, ~8 mm at 0.4 s (the "
        "autofocus removes that much), ~27 mm at 0.5 s (more than a Ku wavelength). At most "
        "latency_budget_s in effect (the pulses wait for the samples after the silence); "
        "<= max_gap_s: no bridging",
        unit="s",
        ge=0,
    )
    clock_step_tolerance_s: float = _key(
        1.0,
        "A change in INS latency (host receive time minus sample time) beyond this is a clock "
        "step: samples are refused (pulses flagged) until the new latency has held 3 s. "
        "Larger than the link's jitter and batching (SBG holds logs until its clock fit)",
        unit="s",
        gt=0,
    )
    gps_minus_utc_s: int = _key(18, "GPS - UTC leap seconds", unit="s", ge=0)
    signing_key_hex: str = _key(
        "", "MAVLink 2 signing key (64 hex digits); when set, unsigned packets are rejected"
    )
    mavlink_system_id: int = _key(
        0,
        "MAVLink system id of the vehicle whose navigation is used; rate requests go to it, "
        "messages of other systems on the link are ignored, named in the log and counted "
        "(ins rejected). 0: the first system whose HEARTBEAT says it is an autopilot (not a "
        "ground station, companion computer, gimbal or camera); a log without one: the first "
        "system heard",
        ge=0,
        le=255,
    )


@dataclass(frozen=True)
class GeometryConfig:
    """Imaging geometry."""

    look_side: Literal["right", "left"] = _key("right", "Side the antenna looks to")
    height_m: float = _key(
        100.0, "Height of the antenna above the flat imaged terrain", unit="m", gt=0
    )
    center_slant_range_m: float = _key(
        900.0, "Scene-centre slant range used for first-order compensation", unit="m", gt=0
    )
    antenna_squint_deg: float = _key(
        0.0,
        "Antenna mount: the antenna turned about body z from broadside to body x (positive: "
        "the beam turns forward). The beam is fixed to the body, so with the INS attitude "
        "this says where it points; a crabbed body squints it further",
        unit="deg",
        gt=-60,
        lt=60,
    )
    antenna_depression_deg: float | None = _key(
        None,
        "Antenna mount: boresight depression below the body's x-y plane; the Doppler "
        "centroid recorded per block is that of the boresight's look angle (90 deg minus "
        "this). Unset: that of the scene centre (center_slant_range_m)",
        unit="deg",
        gt=0,
        lt=90,
    )

    def reference_look_rad(self) -> float:
        """Look angle from the vertical at which the beam-centre squint and the attitude
        Doppler centroid are given (the store's ``doppler`` table), rad: ``90° -
        antenna_depression_deg``, else the scene centre's (``center_slant_range_m`` at
        ``height_m``)."""
        if self.antenna_depression_deg is None:
            return float(look_angle(self.center_slant_range_m, self.height_m))
        return math.radians(90.0 - self.antenna_depression_deg)


@dataclass(frozen=True)
class MocompConfig:
    """INS-only per-pulse motion compensation (docs/methods.md §2)."""

    order: Literal[2] = _key(
        2,
        "2: look angle per range bin and the deviation across the line of sight to second "
        "order, and with the autofocus off the image former removes the eq. 29 squint "
        "residual per pixel. 1 (the scene-centre look angle for every bin) is refused: it "
        "defocuses a real flight",
        refused=(
            (
                1,
                "the scene-centre look angle for every bin leaves a look-angle error across "
                "the swath that the autofocus does not remove (measured in "
                "docs/measurements/acceptance.md); use 2",
            ),
        ),
    )
    envelope_fraction: float = _key(
        DEFAULT_ENVELOPE_FRACTION,
        "Shift pulses in range when |d_los| exceeds this fraction of a range cell (the "
        "envelope error left is at most that: 0.05 keeps 99.6 % of the peak, 0.25 only 90 %, "
        "which in turbulence ripples the aperture's amplitude and costs azimuth PSLR)",
        ge=0,
        le=10,
    )
    along_track: bool = _key(
        True,
        "Place each pulse at its INS along-track position (slow time resampled to "
        "x / v0) for autofocus and image formation, so along-track speed changes come "
        "from the INS; false: uniform speed v0, the autofocus then has to absorb the "
        "speed error as a rate error",
    )
    segments: bool = _key(
        True,
        "Cut the strip into straight reference-track segments (a new track after each "
        "turn and where the INS track leaves the current one by segment_tolerance_m; "
        "pulses in turns are flagged TURN and not imaged); false: one track for the run",
    )
    heading_window_s: float = _key(
        4.0,
        "The first reference track, and with it the along-track axis of the image grid, "
        "follows the mean antenna velocity of this much flight from the first pulse with "
        "navigation (of the whole run when it is shorter) in a replay or batch, which "
        "holds those pulses before focusing (this times the PRF pulses in memory, at most "
        "512 MiB of echoes: shorter at high pulse rates); a live "
        "run holds none and takes the first processing block's mean velocity "
        "(imaging.block_pulses), as does 0. Over a short span turbulence turns the mean "
        "velocity off the course (one 1.3 s block of the acceptance flight: 0.42 deg), and "
        "the image grid with it: targets 130 m apart in range then sit 0.3-0.4 m apart "
        "along track from where they are",
        unit="s",
        ge=0,
    )
    segment_tolerance_m: float = _key(
        3.0,
        "Cross-track/vertical deviation from the reference track at which a new segment "
        "starts (bounds D_los and the envelope shift)",
        unit="m",
        gt=0,
    )


@dataclass(frozen=True)
class AutofocusSection(TilePgaConfig, AutofocusConfig):
    """Sliding-subaperture two-step autofocus (docs/methods.md §3) and tile PGA.

    The settings of the sliding autofocus and of tile PGA are their own classes' fields
    (this section *is* a :class:`~sarmoco.processing.autofocus.settings.AutofocusConfig`,
    handed to the engine as it is, and a
    :class:`~sarmoco.processing.imaging.tile_pga.TilePgaConfig`, handed to tile PGA as it
    is); the daemon adds the two switches.
    """

    enabled: bool = _key(True, "Run the two-step autofocus after INS compensation")
    pga: bool = _key(
        False,
        "Refine every finished stripmap tile with phase gradient autofocus (image-domain "
        "stripmap PGA on the tile and its two neighbours; with or without the sliding "
        "autofocus): removes phase errors shorter than a subaperture; tiles come out one "
        "tile later",
    )


@dataclass(frozen=True)
class ImagingConfig:
    """Image formation: backprojection onto ground tiles along the track."""

    block_pulses: int = _key(256, "Pulses per processing block", gt=0)
    window: Literal["none", "hann", "hamming", "taylor"] = _key(
        "none", "Range-compression weighting"
    )
    pixel_m: float = _key(0.1, "Ground grid spacing", unit="m", gt=0)
    tile_length_m: float = _key(20.0, "Along-track length of one image tile", unit="m", gt=0)
    swath_m: float = _key(
        60.0, "Ground-range width of the tiles, centred on the scene centre", unit="m", gt=0
    )
    azimuth_beamwidth_deg: float = _key(
        3.0,
        "Two-way azimuth beamwidth (the integration angle): a pixel takes only the pulses "
        "that see it within half this plus squint_tolerance_deg of broadside",
        unit="deg",
        gt=0,
        lt=90,
    )
    squint_tolerance_deg: float = _key(
        0.3,
        "Extra squint on each side of the beam that pixels still take, and the pre-filter "
        "passes: covers the heading error of the INS-only reference track against the beam "
        "and spotlight targets off the aperture centre; a wider margin gives each pixel "
        "more pulses of noise beyond its aperture",
        unit="deg",
        ge=0,
        lt=45,
    )
    pointing_uncertainty_deg: float = _key(
        2.0,
        "How far the beam may lie from where the attitude points it, on each side, until "
        "the segment's echoes show where it is: the pixels take the pulses of that much "
        "more squint (an INS heading still converging, a mount or a stabilised antenna that "
        "does not follow the body), as far as the band stays within the pulse rate, in "
        "blocks whose echoes are more than noise; 0 trusts the attitude from the first pulse",
        unit="deg",
        ge=0,
        lt=45,
    )
    prefilter: bool = _key(
        True,
        "Low-pass filter and decimate the pulses in slow time to the Doppler band of "
        "those squints before backprojection",
    )
    prefilter_oversampling: float = _key(
        PREFILTER_OVERSAMPLING,
        "Pulse rate after the pre-filter over the two-sided Doppler band it keeps",
        gt=1,
    )
    presum_first: bool = _key(
        False,
        "Run the pre-filter on the raw echoes, after the per-pulse scene-centre D_los phase "
        "and before range compression: range compression, envelope shift, per-bin D_los, "
        "autofocus and imaging then run at the decimated pulse rate (with prefilter on)",
    )
    method: Literal["direct", "ffbp", "rda", "pfa"] = _key(
        "direct",
        "Tile image formation: direct backprojection, fast factorised backprojection "
        "(polar subimages merged in stages, factorisation set by ffbp_max_phase_error_rad), "
        "the range-Doppler algorithm on blocks of tiles (stripmap), or the polar format "
        "algorithm per tile (spotlight: each tile a scene of its own, its aperture "
        "azimuth_beamwidth_deg about the beam centre). The last two work in the frequency "
        "domain (the live imagers: their cost is per sample, not per pixel and pulse) and "
        "resample onto the same ground tiles",
    )
    live_method: Literal["method", "rda", "pfa"] = _key(
        "method",
        "Tile image formation of a live run (sarmoco run): method (the same as replay "
        "and batch), or a live imager (rda, pfa) while replay and batch form the full "
        "image with method",
    )
    live_degrade: bool = _key(
        True,
        "With method rda or pfa in a live run: the rda tiles start in blocks of tiles; "
        "when focusing has room for it, form each alone as soon as its pulses are in (the "
        "same image, up to three tile lengths of flight sooner, costlier per tile; the status "
        "gauge live_image_prompt); when focusing needs more than live_budget of real time, "
        "form them in blocks again, then at a degraded level (1: twice the pixel spacing "
        "and, for rda, a presum by 2: half the Doppler band, twice the azimuth resolution; 2: "
        "also half the swath; 3: four times the pixel spacing, presum by 4, half the "
        "swath), one step up at a time, and "
        "back down when the step below, at its measured cost, would fit with a margin; the "
        "level is the status gauge live_image_level. A replay never degrades",
    )
    live_min_level: int = _key(
        0,
        "With live_degrade: the lowest degraded level the live tiles are formed at (0: full "
        "resolution, tiles in blocks or, with room, prompt; above 0: in blocks); the rule "
        "moves between it and the last level",
        ge=0,
        le=len(LEVELS) - 1,
    )
    live_budget: float = _key(
        0.8,
        "Share of real time the live imager may spend focusing before it steps up (tiles in "
        "blocks, then degraded levels; focusing CPU seconds per second of data, averaged "
        "over live_window_s)",
        gt=0,
    )
    live_window_s: float = _key(
        5.0, "Seconds of data over which the live imager's load is averaged", unit="s", gt=0
    )
    north_up: bool = _key(
        True,
        "After a replay or batch, also resample each reference-track segment's tiles onto a "
        "north/east grid of the same spacing, phase kept (the store's north_up group, NED "
        "about the origin the INS named for its positions; none where it named none): the "
        "tiles' grid turns with the course flown, this one does not",
    )
    ffbp_max_phase_error_rad: float = _key(
        0.3,
        "With method ffbp: bound on the two-way phase error of the factorisation summed over "
        "its stages (angle sampling pi L dalpha / lambda per stage); a larger budget means "
        "fewer angle samples and higher sidelobes",
        unit="rad",
        gt=0,
        lt=math.pi,
    )

    def imaged_beam_rad(self) -> float:
        """Azimuth beam the pixels take: ``azimuth_beamwidth_deg`` plus
        ``squint_tolerance_deg`` on each side, rad."""
        return math.radians(self.azimuth_beamwidth_deg + 2.0 * self.squint_tolerance_deg)


@dataclass(frozen=True)
class ArrayConfig:
    """MIMO downward-looking array (radar.mode = "array"; docs/methods.md §4).

    Elements lie on the wing (body y axis) about the antenna reference point
    (``ins.lever_arm_m`` from the IMU) in the filled MIMO layout
    (:func:`~sarmoco.processing.array.geometry.mimo_layout`): receivers ``2 d`` apart,
    transmitters ``n_rx 2 d`` apart, so that the equivalent phase centres of the pairs are one
    uniform virtual array of spacing ``d = epc_spacing_m``. Pair ``m * n_rx + n`` (Tx ``m``,
    Rx ``n``) arrives on VITA stream ID ``stream_ids[m * n_rx + n]`` (``m * n_rx + n`` when
    ``stream_ids`` is empty).
    """

    n_tx: int = _key(2, "Transmitters across the wing", gt=0)
    n_rx: int = _key(80, "Receivers across the wing", gt=0)
    stream_ids: tuple[int, ...] = _key(
        (),
        "VITA stream identifier (the digitiser's own 32-bit values) of each Tx/Rx pair, in "
        "pair order m * n_rx + n (Tx m, Rx n): n_tx * n_rx distinct values; signal packets "
        "of other streams are counted and skipped. Empty: 0 .. n_tx * n_rx - 1",
        ge=0,
        le=0xFFFFFFFF,
    )
    epc_spacing_m: float = _key(
        0.02,
        "Spacing d of the equivalent phase centres (virtual array) along the wing",
        unit="m",
        gt=0,
    )
    antenna_length_m: float = _key(
        1.0,
        "Along-track length D of the elements: the imager keeps the Doppler band "
        "|k_x| <= 4 pi / D (2 v / D in Hz, at most the PRF); along-track resolution D / 2",
        unit="m",
        gt=0,
    )
    max_look_deg: float = _key(
        20.0, "Largest cross-track look angle from nadir imaged", unit="deg", gt=0, lt=90
    )
    sub_blocks: tuple[int, int] = _key(
        (1, 8),
        "Sub-blocks of the second roll compensation in (k_x, k_y): along-track by cross-track "
        "wavenumber blocks (1, 1: one phase for the whole spectrum)",
        ge=1,
    )
    dem_spacing_m: float = _key(0.5, "Cross-track grid spacing of the DEM product", unit="m", gt=0)
    roll_compensation: bool = _key(
        True, "Compensate the roll error (both steps); false images with the nominal geometry"
    )
    record_uncompensated: bool = _key(
        True, "Also image without roll compensation and record that DEM beside the product"
    )


@dataclass(frozen=True)
class RecorderConfig:
    """Zarr v3 recording of each run."""

    directory: str = _key("/var/lib/sarmoco", "Directory that receives one store per run")
    raw_echoes: bool = _key(True, "Record the raw echoes")
    raw_ins: bool = _key(
        True, "Record the INS bytes as received (ins_raw / ins_bytes; MAVLink, SBG, SBG CAN)"
    )
    chunk_pulses: int = _key(256, "Pulses per chunk of the echo arrays", gt=0)
    echo_compression: str = _key(
        "none",
        "Lossless compression of the raw echoes: 'lz4-bitshuffle' stores noise-like int16 "
        "echoes in less space at the cost of CPU on the recording path (both measured in "
        "docs/measurements/ingest.md); 'none' stores them as they are",
        choices=tuple(ECHO_COMPRESSION),
    )
    fsync_interval_s: float = _key(1.0, "Interval between fsyncs of committed data", unit="s", gt=0)
    flush_interval_s: float = _key(
        0.25,
        "Longest time rows of the per-pulse and INS tables wait in memory before they are "
        "written (each file the store writes costs about a millisecond of CPU, so small "
        "blocks are gathered); a crash loses at most this much of them. Raw echoes are "
        "written a whole chunk at a time either way. 0: every block is written as it comes",
        unit="s",
        ge=0,
    )
    writer_queue: int = _key(
        0,
        "Writes (blocks of pulses, tiles, table rows) that may wait for the recorder's writer "
        "thread while recording and focusing go on; when it is full, they wait. 0: the "
        "recording thread and the focusing loop write themselves",
        ge=0,
    )


@dataclass(frozen=True)
class StatusConfig:
    """Local status endpoint and logging."""

    http_port: int = _key(
        9108,
        "TCP port on 127.0.0.1 for /status (JSON) and /metrics (Prometheus); 0 disables",
        ge=0,
        le=65535,
    )
    live_render_interval_s: float = _key(
        1.0,
        "Shortest time between two renderings of the live page's tile strip (rendered in "
        "the HTTP thread, only when a tile was added)",
        unit="s",
        gt=0,
    )
    log_level: Literal["debug", "info", "warning", "error"] = _key("info", "Log level")


@dataclass(frozen=True)
class LimitsConfig:
    """What a run may ask of the machine (checked by ``config check``, ``run`` and ``replay``
    before anything is allocated; :mod:`sarmoco.daemon.resources`)."""

    memory_mib: float = _key(
        0.0,
        "Memory the run's buffers (echo ring, focus backlog, focusing block, image tile, "
        "recorder chunk and queue) may take together; a configuration whose buffers need "
        "more is refused, naming the key. 0: the machine's memory (physical, or the "
        "cgroup's limit when lower)",
        unit="MiB",
        ge=0,
    )
    data_rate_mbps: float = _key(
        0.0,
        "Highest echo data rate (radar.prf_hz x radar.n_samples x bytes per sample x "
        "channels) accepted, e.g. what the recording disk sustains; 0: no limit",
        unit="Mbit/s",
        ge=0,
    )


@dataclass(frozen=True)
class CameraConfig:
    """The radar as a MAVLink camera component (camera protocol v2) for the ground station."""

    enabled: bool = _key(
        False,
        "Speak as a MAVLink camera component: HEARTBEAT, CAMERA_INFORMATION, capture "
        "commands and STATUSTEXT for faults",
    )
    link: str = _key(
        "udpout:127.0.0.1:14550",
        "pymavlink connection string of the camera component's link (a mavlink-router or "
        "autopilot endpoint that reaches the ground station)",
    )
    system_id: int = _key(1, "MAVLink system id of the camera component (the vehicle's)", ge=1,
                          le=255)  # fmt: skip
    component_id: int = _key(
        100, "MAVLink component id of the camera component (100: MAV_COMP_ID_CAMERA)", ge=1,
        le=255,
    )  # fmt: skip
    model: str = _key(
        "", "Model name in CAMERA_INFORMATION; empty: 'SAR' with the carrier frequency"
    )
    command_system_ids: tuple[int, ...] = _key(
        (255, 245, 1),
        "MAVLink system ids whose commands are taken (255: QGroundControl, Mission Planner, "
        "MAVProxy; 245: MAVSDK ground stations; 1: the autopilot); commands from others "
        "are refused, counted and logged",
    )
    signing_key_hex: str = _key(
        "",
        "MAVLink 2 signing key of the camera link (64 hex digits); when set, unsigned and "
        "badly signed packets are rejected (camera_unsigned_rejected) and the component "
        "signs what it sends",
    )
    capture_at_start: bool = _key(
        True,
        "Capture from the start of the daemon to its stop (benches, vehicles without a "
        "ground station); false: pulses are recorded only between start and stop capture "
        "commands",
    )
    store_per_capture: bool = _key(
        False,
        "Open a new store at each start capture command and close it at the stop (a store "
        "per strip, named by UTC time and mission item); false: one store from the start of "
        "the daemon to its stop",
    )
    statustext_interval_s: float = _key(
        10.0, "Interval between repeats of the STATUSTEXT of a fault that lasts", unit="s", gt=0
    )
    disk_low_fraction: float = _key(
        0.05, "Free share of the store's file system below which the disk counts as nearly "
        "full", gt=0, lt=1,
    )  # fmt: skip


@dataclass(frozen=True)
class Config:
    """The whole daemon configuration."""

    radar: RadarConfig = field(default_factory=RadarConfig)
    ins: InsConfig = field(default_factory=InsConfig)
    geometry: GeometryConfig = field(default_factory=GeometryConfig)
    mocomp: MocompConfig = field(default_factory=MocompConfig)
    autofocus: AutofocusSection = field(default_factory=AutofocusSection)
    imaging: ImagingConfig = field(default_factory=ImagingConfig)
    array: ArrayConfig = field(default_factory=ArrayConfig)
    recorder: RecorderConfig = field(default_factory=RecorderConfig)
    status: StatusConfig = field(default_factory=StatusConfig)
    limits: LimitsConfig = field(default_factory=LimitsConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration file.

    Parameters
    ----------
    path : str or Path
        The TOML file.

    Returns
    -------
    Config
        The frozen configuration, defaults filled in.

    Raises
    ------
    ConfigError
        If the file cannot be read or parsed, or any key is unknown or invalid.
    """
    p = Path(path)
    try:
        with p.open("rb") as fh:
            table = tomllib.load(fh)
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read: {exc.strerror}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not UTF-8 text (TOML is UTF-8): {exc}") from exc
    return parse_config(table)


def parse_config(table: Mapping[str, Any]) -> Config:
    """Validate a parsed TOML table into a :class:`Config`.

    Raises
    ------
    ConfigError
        Naming the key path, the bad value and what is allowed, or (:func:`check_geometry`)
        the keys of a radar and geometry that cannot be imaged together.
    """
    cfg: Config = _build(Config, table, "")
    check_channels(cfg.radar, cfg.array)
    check_ins_rate(cfg.ins)
    if cfg.radar.mode == "array":
        check_array(cfg)
    else:
        check_geometry(cfg)
        check_tiles(cfg.imaging)
    return cfg


def check_ins_rate(ins: InsConfig) -> None:
    """Refuse an INS rate whose sample interval no pulse can be interpolated across.

    A pulse is focused when INS samples bracket it no further apart than the longer of
    ``ins.max_gap_s`` and ``ins.bridge_gap_s``, and it waits for the sample after it at
    most ``ins.latency_budget_s``.

    Raises
    ------
    ConfigError
        ``1 / ins.rate_hz`` longer than either.
    """
    interval = 1.0 / ins.rate_hz
    longest = max(ins.max_gap_s, ins.bridge_gap_s)
    if interval > longest:
        raise ConfigError(
            f"ins.rate_hz: {ins.rate_hz!r} Hz gives INS samples {interval:.4g} s apart, longer "
            f"than the longest interval a pulse is interpolated across (ins.max_gap_s "
            f"{ins.max_gap_s!r} s, ins.bridge_gap_s {ins.bridge_gap_s!r} s): no pulse would "
            "be bracketed"
        )
    if interval > ins.latency_budget_s:
        raise ConfigError(
            f"ins.rate_hz: {ins.rate_hz!r} Hz gives INS samples {interval:.4g} s apart, longer "
            f"than ins.latency_budget_s {ins.latency_budget_s!r} s: pulses would time out "
            "waiting for the sample after them"
        )


def check_tiles(imaging: ImagingConfig) -> None:
    """Refuse a pixel that does not fit in its tile.

    Raises
    ------
    ConfigError
        ``imaging.pixel_m`` larger than ``imaging.tile_length_m`` or ``imaging.swath_m``.
    """
    for key, extent in (("tile_length_m", imaging.tile_length_m), ("swath_m", imaging.swath_m)):
        if imaging.pixel_m > extent:
            raise ConfigError(
                f"imaging.pixel_m: {imaging.pixel_m!r} m is larger than imaging.{key} "
                f"{extent!r} m (a tile holds at least one pixel each way)"
            )


def check_channels(radar: RadarConfig, array: ArrayConfig) -> None:
    """Refuse a channel count the mode cannot use.

    Raises
    ------
    ConfigError
        Single mode with ``radar.channels`` > 1; array mode with ``radar.channels`` other
        than ``array.n_tx * array.n_rx``, or ``array.stream_ids`` not one distinct ID per
        pair.
    """
    if radar.mode == "array":
        pairs = array.n_tx * array.n_rx
        if radar.channels != pairs:
            raise ConfigError(
                f"radar.channels: {radar.channels} is not array.n_tx * array.n_rx = "
                f"{array.n_tx} * {array.n_rx} = {pairs} (array mode takes one stream ID per "
                "Tx/Rx pair)"
            )
        ids = array.stream_ids
        if ids and len(ids) != pairs:
            raise ConfigError(
                f"array.stream_ids: {len(ids)} stream IDs for array.n_tx * array.n_rx = "
                f"{pairs} Tx/Rx pairs (one per pair, or none for 0 .. {pairs - 1})"
            )
        if len(set(ids)) != len(ids):
            twice = sorted({i for i in ids if ids.count(i) > 1})
            raise ConfigError(
                f"array.stream_ids: stream IDs {', '.join(map(str, twice))} name more than "
                "one Tx/Rx pair"
            )
    elif radar.channels > 1:
        raise ConfigError(
            f"radar.channels: {radar.channels}: single mode focuses one channel (each channel "
            "would need its own aperture and image set); set radar.channels = 1: the daemon "
            "focuses the VITA stream radar.stream_id and counts and skips the packets of other "
            "stream IDs; "
            'or radar.mode = "array" for a MIMO array (channels = array.n_tx * array.n_rx)'
        )


def array_stream_ids(cfg: Config) -> tuple[int, ...]:
    """VITA stream ID of each Tx/Rx pair of an array, in pair order (``array.stream_ids``)."""
    return cfg.array.stream_ids or tuple(range(cfg.array.n_tx * cfg.array.n_rx))


def check_array(cfg: Config) -> None:
    """Refuse an array whose settings cannot give a DEM.

    Raises
    ------
    ConfigError
        Naming the key: fewer than two channels (no virtual array), a matched-filter receiver
        missing (``radar.receive``), or a range window that does not hold the nadir range
        ``geometry.height_m``.
    """
    a, r = cfg.array, cfg.radar
    if a.n_tx * a.n_rx < 2:
        raise ConfigError(
            f"array.n_rx: {a.n_tx} * {a.n_rx} Tx/Rx pairs make no virtual array (at least 2)"
        )
    if r.receive != "matched":
        raise ConfigError(f"radar.receive: {r.receive!r}: the array imager needs 'matched'")
    near, far = r.slant_window_m()
    h = cfg.geometry.height_m
    if not near < h < far:
        raise ConfigError(
            f"geometry.height_m: {h!r} m (the nadir range) is outside the range window "
            f"{near:.2f} .. {far:.2f} m (radar.range_gate_delay_s {r.range_gate_delay_s!r} s, "
            f"radar.n_samples {r.n_samples!r})"
        )


def check_geometry(cfg: Config) -> None:
    """Refuse a range window and imaging geometry that cannot give an image.

    The range window is :meth:`RadarConfig.slant_window_m`; the scene centre is at
    ``geometry.center_slant_range_m`` and ground range ``sqrt(R_c**2 - H**2)``, the imaged
    swath ``imaging.swath_m`` of ground range centred on it.

    Raises
    ------
    ConfigError
        Naming the keys and values when the scene centre is not beyond the nadir range
        (R_c <= H), the window starts inside the nadir range (first bin < H: the look angle of
        those bins does not exist), or the scene centre or the swath lies outside the window
        (or the swath reaches past nadir).
    """
    r, geo, swath = cfg.radar, cfg.geometry, cfg.imaging.swath_m
    h, r_c = geo.height_m, geo.center_slant_range_m
    if r_c <= h:
        raise ConfigError(
            f"geometry.center_slant_range_m: {r_c!r} m is not > geometry.height_m {h!r} m "
            "(a scene centre at or inside the nadir range cannot be imaged)"
        )
    near, far = r.slant_window_m()
    window = (
        f"the range window {near:.2f} .. {far:.2f} m (radar.range_gate_delay_s "
        f"{r.range_gate_delay_s!r} s, radar.n_samples {r.n_samples!r}, radar.sample_rate_hz "
        f"{r.sample_rate_hz!r} Hz, radar.receive {r.receive!r})"
    )
    if near < h:
        remedy = (
            f"raise it to at least {2.0 * h / C_MPS:.4g} s"
            if r.receive == "matched"
            else "the dechirp window reaches c f_s / 4K = "
            f"{C_MPS * r.sample_rate_hz * r.pulse_width_s / (4.0 * r.bandwidth_hz):.2f} m either "
            "side of the reference: lower radar.sample_rate_hz (decimate)"
        )
        raise ConfigError(
            f"radar.range_gate_delay_s: {r.range_gate_delay_s!r} s starts {window} inside the "
            f"nadir range geometry.height_m {h!r} m (no ground at those ranges); {remedy}, or "
            "check geometry.height_m"
        )
    if not near <= r_c <= far:
        raise ConfigError(f"geometry.center_slant_range_m: {r_c!r} m is outside {window}")
    ground_c = math.sqrt((r_c - h) * (r_c + h))  # r_c**2 overflows for r_c > 1.3e154
    if swath / 2.0 >= ground_c:
        raise ConfigError(
            f"imaging.swath_m: {swath!r} m reaches past nadir (the scene centre's ground range "
            f"is {ground_c:.2f} m: geometry.center_slant_range_m {r_c!r} m, geometry.height_m "
            f"{h!r} m)"
        )
    lo, hi = math.hypot(ground_c - swath / 2.0, h), math.hypot(ground_c + swath / 2.0, h)
    if lo < near or hi > far:
        raise ConfigError(
            f"imaging.swath_m: {swath!r} m about geometry.center_slant_range_m {r_c!r} m spans "
            f"slant ranges {lo:.2f} .. {hi:.2f} m, outside {window}"
        )


def _build(cls: type, table: Any, prefix: str) -> Any:
    if not isinstance(table, Mapping):
        raise ConfigError(f"{prefix or '<root>'}: {table!r} is not a table")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - set(fields))
    if unknown:
        where = f"{prefix}.{unknown[0]}" if prefix else unknown[0]
        raise ConfigError(f"{where}: unknown key (allowed: {', '.join(sorted(fields))})")
    values = {}
    for name, value in table.items():
        path = f"{prefix}.{name}" if prefix else name
        values[name] = _coerce(hints[name], value, path, fields[name].metadata)
    try:
        return cls(**values)
    except ProcessingError as exc:  # a section's own cross-key check (AutofocusConfig)
        raise ConfigError(f"{prefix}: {exc}") from exc


def _coerce(tp: Any, value: Any, path: str, meta: Mapping[str, Any]) -> Any:
    if dataclasses.is_dataclass(tp):
        return _build(typing.cast(type, tp), value, path)
    for bad, reason in meta.get("refused", {}).items():
        if value == bad and type(value) is type(bad):
            raise ConfigError(f"{path}: {value!r} is refused: {reason}")
    origin = typing.get_origin(tp)
    if origin is Literal:
        allowed = typing.get_args(tp)
        if value not in allowed or type(value) is not type(allowed[0]):
            raise ConfigError(f"{path}: {value!r} is not one of {', '.join(map(repr, allowed))}")
        return value
    if origin is tuple and typing.get_args(tp)[1:] == (Ellipsis,):
        if not isinstance(value, list):
            raise ConfigError(f"{path}: {value!r} is not a list")
        item = typing.get_args(tp)[0]
        return tuple(_coerce(item, v, f"{path}[{i}]", meta) for i, v in enumerate(value))
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list) or len(value) != len(args):
            raise ConfigError(f"{path}: {value!r} is not a list of {len(args)} numbers")
        return tuple(
            _coerce(a, v, f"{path}[{i}]", meta)
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (typing.Union, types.UnionType):
        members = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(members) != 1 or len(typing.get_args(tp)) != 2:
            raise TypeError(f"{path}: only `T | None` unions are supported in config sections")
        return None if value is None else _coerce(members[0], value, path, meta)
    return _scalar(tp, value, path, meta)


def _scalar(tp: type, value: Any, path: str, meta: Mapping[str, Any]) -> Any:
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: {value!r} is not true or false")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: {value!r} is not a string")
        choices = meta.get("choices")
        if choices and value not in choices:
            raise ConfigError(f"{path}: {value!r} is not one of {', '.join(map(repr, choices))}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: {value!r} is not an integer")
        if not -(2**63) <= value < 2**63:
            raise ConfigError(f"{path}: {value!r} is outside TOML's 64-bit integer range")
    elif tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{path}: {value!r} is not a number")
        if not abs(value) <= sys.float_info.max:  # NaN, inf, or an int beyond any float
            raise ConfigError(f"{path}: {value!r} is not a finite number")
    for bound, test, word in (
        ("gt", lambda v, b: v > b, ">"),
        ("ge", lambda v, b: v >= b, ">="),
        ("lt", lambda v, b: v < b, "<"),
        ("le", lambda v, b: v <= b, "<="),
    ):
        b = meta.get(bound)
        if b is not None and not test(value, b):
            raise ConfigError(f"{path}: {value!r} is not {word} {b:g}")
    return float(value) if tp is float else value


def describe_keys() -> list[dict[str, str]]:
    """List every key with its type, unit, default and constraints (for docs/configuration.md).

    Returns
    -------
    list of dict
        One row per key: ``key``, ``type``, ``unit``, ``default``, ``allowed``, ``doc``.
    """
    rows: list[dict[str, str]] = []
    hints = typing.get_type_hints(Config)
    for section in dataclasses.fields(Config):
        sec_cls = hints[section.name]
        sec_hints = typing.get_type_hints(sec_cls)
        for f in dataclasses.fields(sec_cls):
            tp = sec_hints[f.name]
            allowed = _allowed_text(tp, f.metadata)
            rows.append(
                {
                    "key": f"{section.name}.{f.name}",
                    "type": _type_text(tp),
                    "unit": f.metadata.get("unit", ""),
                    "default": _toml_value(f.default),
                    "allowed": allowed,
                    "doc": f.metadata.get("doc", ""),
                }
            )
    return rows


def keys_markdown() -> str:
    """Every key as a Markdown table (the table of docs/configuration.md); a ``|`` in a
    key's meaning (``|d_los|``) is escaped so that it stays in its cell."""
    lines = ["| key | type | unit | default | allowed | meaning |", "|---|---|---|---|---|---|"]
    for r in describe_keys():
        doc = r["doc"].replace("|", r"\|")
        lines.append(
            f"| `{r['key']}` | {r['type']} | {r['unit']} | `{r['default']}` | {r['allowed']} | "
            f"{doc} |"
        )
    return "\n".join(lines) + "\n"


def _type_text(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return _type_text(next(a for a in typing.get_args(tp) if a is not type(None)))
    if origin is Literal:
        return "string" if isinstance(typing.get_args(tp)[0], str) else "integer"
    if origin is tuple and typing.get_args(tp)[1:] == (Ellipsis,):
        return f"array of {_type_text(typing.get_args(tp)[0])}s"
    if origin is tuple:
        return f"array of {len(typing.get_args(tp))} numbers"
    return {bool: "boolean", int: "integer", float: "number", str: "string"}[tp]


def _allowed_text(tp: Any, meta: Mapping[str, Any]) -> str:
    if typing.get_origin(tp) is Literal:
        return ", ".join(_toml_value(a) for a in typing.get_args(tp))
    if meta.get("choices"):
        return ", ".join(_toml_value(a) for a in meta["choices"])
    words = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}
    return ", ".join(
        f"{w} {meta[k] if isinstance(meta[k], int) else format(meta[k], 'g')}"
        for k, w in words.items()
        if meta.get(k) is not None
    )


def _toml_value(v: Any) -> str:
    if v is None:
        return "unset"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return f"{v:g}" if isinstance(v, float) else str(v)


def config_to_dict(cfg: Config) -> dict[str, Any]:
    """Return the configuration as plain dicts and lists (JSON-able, for recorder attributes;
    :func:`parse_config` takes it back: a tuple key is a TOML array, a list)."""
    return typing.cast(dict[str, Any], _plain(dataclasses.asdict(cfg)))


def _plain(value: Any) -> Any:
    """``value`` with every tuple made a list, in dicts and lists at any depth."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def live_imaging(cfg: Config) -> Config:
    """The configuration a live run focuses with: ``imaging.live_method`` as the tile
    imager (unless it is ``"method"``); the store records ``cfg`` itself, so a replay of it
    forms the full image with ``imaging.method``."""
    im = cfg.imaging
    if im.live_method == "method":
        return cfg
    return dataclasses.replace(cfg, imaging=dataclasses.replace(im, method=im.live_method))
