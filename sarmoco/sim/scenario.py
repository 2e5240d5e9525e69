"""Simulated acquisition scenarios: radar, nominal flight line, scene, loaded from TOML presets.

Nominal geometry, in the *track frame* (x along the nominal track, y across it toward the
side the antenna looks, z down; m): the platform flies along +x at ``speed_mps`` at depth
``-altitude_m`` (the ground is the plane ``z = 0``), along the line ``y = 0``. The scene
centre is at x 0, y ``sqrt(R_c**2 - H**2)``; the track starts at ``track_start_north_m`` (along
x) so that the scene is at broadside mid-aperture. The track frame is placed in local NED by
the heading ``heading_rad`` (x toward north rotated by the heading toward east) and the look
side (``look_side``: the track frame's y is the right of the track for "right", its left for
"left"): see :meth:`Scenario.to_ned`. With the defaults (heading 0, looking right) the two
frames coincide. Target positions and ``scene_center_ned`` are stored in NED; target
overrides given to :func:`load_preset` are in the track frame. The antenna phase centre sits
``lever_arm_m`` (body frame: forward, right, down) from the INS point that the trajectory
describes.

Wind: a platform in a crosswind flies *crabbed*: its body is yawed against the ground track by
``crab_rad`` (body yaw minus track heading, rad, positive clockwise seen from above, i.e. from
north toward east; a crosswind ``w`` across an airspeed ``V_a`` gives ``|crab| = asin(w / V_a)``,
the nose turned into the wind). The platform still flies the nominal track (the ground
velocity is along it); its steady attitude is level at yaw ``heading_rad + crab_rad``
(:attr:`Scenario.body_to_ned`), and the INS reports that yaw.

Antenna: fixed to the body. Its boresight lies in the body's horizontal plane at the look
side's broadside (body +y looking right, -y looking left), turned toward the body's nose
(+x) by the mount's squint ``antenna_squint_rad`` (rad, positive forward). The stripmap beam
is an ideal rectangular fan beam: a cone about the antenna's array axis (the body-horizontal
axis normal to the boresight; body x when unsquinted) that lights a target while its
direction makes an angle of at most half the integration angle with the plane normal to that
axis (:meth:`Scenario.illumination`). A rotation of the antenna about its array axis (a
depression) leaves such a beam unchanged. The beam follows the platform's steady attitude:
the crab and the mount squint it, the attitude's fast motion (turbulence, a logged flight's
wander) does not steer it. Its squint from the track's broadside, positive forward, is
``antenna_squint_rad - crab_rad`` looking right and ``antenna_squint_rad + crab_rad`` looking
left (:attr:`Scenario.beam_squint_rad`); the aperture is placed so that every target crosses
the squinted beam. Simulation time ``t_s`` counts seconds from the first pulse, whose GPS
time is ``t0_ns``.

Presets (``sarmoco/sim/presets/*.toml``) hold the papers' numbers (docs/methods.md §6) and say in
comments which values are our own choices. ``scale`` (0 < scale <= 1) shrinks the swath, the
pulse width (hence the fast-time samples) and the PRF (down to twice the Doppler bandwidth) for
fast tests, keeping carrier, bandwidth, sample rate, integration angle and therefore both
resolutions; the aperture time is set by the azimuth resolution and is not shrunk, except for
the part a stripmap aperture spends on the (scaled) along-track extent of the scene.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from importlib import resources
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from sarmoco.errors import ConfigError
from sarmoco.processing.types import C_MPS, FloatArray, RadarParams

PRESETS = ("thz-spotlight", "ku-vehicle", "ku-microuav")
"""Names of the shipped scenario presets."""

DEFAULT_T0_NS = 1_400_000_000 * 1_000_000_000
"""GPS time of the first pulse of a simulated run, ns (2024-05-18)."""

RANGE_MARGIN_FRACTION = 0.05
"""Extra slant range kept on each side of the swath in the range window, fraction of its extent."""

RANGE_MARGIN_M = 3.0
"""Extra slant range kept on each side of the swath (motion deviations), m."""

PRF_OVERSAMPLING = 2.0
"""A scaled PRF never drops below this multiple of the scene's Doppler bandwidth."""

DEFAULT_LEVER_ARM_M = (0.30, 0.15, 0.20)
"""INS-to-antenna phase centre offset of a simulated platform, body frame (forward, right,
down), m (0.39 m: an IMU in the fuselage, the antenna under the nose/side)."""


@dataclass(frozen=True)
class Target:
    """A point scatterer.

    Parameters
    ----------
    pos_ned : tuple of float
        Position in local NED, m.
    amplitude : complex
        Complex reflectivity (echo amplitude per sample before compression, unit = SNR reference).
    """

    pos_ned: tuple[float, float, float]
    amplitude: complex = 1.0


@dataclass(frozen=True, eq=False)
class Clutter:
    """Distributed scatterers of an extended scene (:mod:`sarmoco.sim.extended`).

    Parameters
    ----------
    pos_ned : ndarray of float64, shape (K, 3)
        Scatterer positions, NED, m.
    amplitude : ndarray of complex128, shape (K,)
        Complex reflectivity of each scatterer (unit: a unit point target's).
    x_m, y_m : ndarray of float64
        The scatterers' grid in the track frame (along track x, ground range y), m.
    reflectivity : ndarray of float64, shape (x_m.size, y_m.size)
        The mean power reflectivity map on that grid (amplitude² / its scale), in [0, 1].
    """

    pos_ned: FloatArray
    amplitude: npt.NDArray[np.complex128]
    x_m: FloatArray
    y_m: FloatArray
    reflectivity: FloatArray


@dataclass(frozen=True)
class Scenario:
    """One simulated acquisition (see the module docstring for the geometry).

    Parameters
    ----------
    name : str
        Preset name.
    radar : RadarParams
        Waveform and receiver.
    speed_mps : float
        Nominal ground speed along +north, m/s.
    altitude_m : float
        APC height above the flat ground, m.
    center_slant_range_m : float
        Broadside slant range to the scene centre, m.
    swath_m : float
        Ground-range extent of the scene, m (scaled).
    mode : {"stripmap", "spotlight"}
        Stripmap: fixed broadside rect beam of ``integration_angle_rad``; spotlight: the beam
        follows the scene centre and every target is lit during the whole aperture.
    aperture_s : float
        Simulated duration, s.
    targets : tuple of Target
        Point scatterers.
    snr_db : float or None
        Per-sample SNR of a unit target before compression, dB; None: no noise.
    scale : float
        The scale the preset was loaded with.
    scene_center_ned : tuple of float
        Scene centre, NED, m.
    integration_angle_rad : float
        Azimuth angle spanned by the synthetic aperture, rad (stripmap: the rect real beam).
    track_start_north_m : float
        North position of the nominal APC at the first pulse, m.
    t0_ns : int
        GPS time of the first pulse, ns.
    heading_rad : float
        Heading of the nominal track, rad from north toward east.
    look_side : {"right", "left"}
        Side of the track the antenna looks to.
    lever_arm_m : tuple of 3 float
        INS point to antenna phase centre, body frame (forward, right, down), m.
    crab_rad : float
        Body yaw minus track heading (a crosswind's crab), rad, positive clockwise from above.
    antenna_squint_rad : float
        The antenna mount's boresight yaw from the look side's body broadside toward the
        body's nose, rad (positive forward).
    clutter : Clutter or None
        Distributed scatterers besides ``targets`` (the extended scene), or None.
    """

    name: str
    radar: RadarParams
    speed_mps: float
    altitude_m: float
    center_slant_range_m: float
    swath_m: float
    mode: Literal["stripmap", "spotlight"]
    aperture_s: float
    targets: tuple[Target, ...]
    snr_db: float | None
    scale: float
    scene_center_ned: tuple[float, float, float]
    integration_angle_rad: float
    track_start_north_m: float
    t0_ns: int = DEFAULT_T0_NS
    heading_rad: float = 0.0
    look_side: Literal["right", "left"] = "right"
    lever_arm_m: tuple[float, float, float] = DEFAULT_LEVER_ARM_M
    crab_rad: float = 0.0
    antenna_squint_rad: float = 0.0
    notes: dict[str, float] = field(default_factory=dict, compare=False)
    clutter: Clutter | None = field(default=None, compare=False)

    @property
    def track_to_ned(self) -> FloatArray:
        """Rotation (and mirror, looking left) from the track frame to NED, (3, 3)."""
        return _track_to_ned(self.heading_rad, self.look_side)

    @property
    def heading_to_ned(self) -> FloatArray:
        """Rotation by the heading alone (the platform's forward/right/down axes), (3, 3)."""
        return _track_to_ned(self.heading_rad, "right")

    @property
    def body_to_ned(self) -> FloatArray:
        """Rotation from the body's forward/right/down axes to NED at the steady attitude
        (level, yaw ``heading_rad + crab_rad``), (3, 3)."""
        return _track_to_ned(self.heading_rad + self.crab_rad, "right")

    @property
    def beam_squint_rad(self) -> float:
        """Squint of the beam centre from the track's broadside, rad, positive forward."""
        return _beam_squint(self.antenna_squint_rad, self.crab_rad, self.look_side)

    @property
    def beam_axis_ned(self) -> FloatArray:
        """The antenna's array axis at the steady attitude, NED unit vector, (3,): the axis of
        the stripmap beam's cone (the track direction when nothing squints the beam)."""
        s = self.antenna_squint_rad
        toward_look = 1.0 if self.look_side == "right" else -1.0
        return self.body_to_ned @ np.array([math.cos(s), -toward_look * math.sin(s), 0.0])

    @property
    def doppler_centroid_hz(self) -> float:
        """Doppler frequency of the scene centre as it crosses the beam centre, Hz.

        ``2 v sin(angle from broadside) / lambda`` for the nominal track (positive: the
        scene centre approaches); 0 unless the beam is squinted.
        """
        ground = math.sqrt(self.center_slant_range_m**2 - self.altitude_m**2)
        along = ground * math.tan(self.beam_squint_rad)
        sin_off = along / math.hypot(along, self.center_slant_range_m)
        return 2.0 * self.speed_mps * sin_off / self.radar.wavelength_m

    @property
    def n_pulses(self) -> int:
        """Number of pulses in the aperture at the nominal PRF."""
        return math.floor(self.aperture_s * self.radar.prf_hz) + 1

    @property
    def azimuth_resolution_m(self) -> float:
        """Azimuth resolution lambda / (4 sin(theta/2)) of the integration angle, m."""
        return self.radar.wavelength_m / (4.0 * math.sin(self.integration_angle_rad / 2.0))

    @property
    def grazing_rad(self) -> float:
        """Grazing angle at the scene centre, rad."""
        return math.asin(self.altitude_m / self.center_slant_range_m)

    def ideal_track(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Nominal straight, level, constant-speed APC track.

        Parameters
        ----------
        t_s : ndarray of float64, shape (P,)
            Time since the first pulse, s.

        Returns
        -------
        pos_ned, vel_ned : ndarray of float64, shape (P, 3)
            Position (m) and velocity (m/s) in NED.
        """
        pos, vel = level_track(t_s, self.track_start_north_m, self.speed_mps, self.altitude_m)
        rot = self.track_to_ned
        return pos @ rot.T, vel @ rot.T

    def targets_array(self) -> tuple[FloatArray, np.ndarray]:
        """Targets as arrays: positions (K, 3) NED in m, complex amplitudes (K,)."""
        pos = np.array([t.pos_ned for t in self.targets], dtype=np.float64).reshape(-1, 3)
        amp = np.array([t.amplitude for t in self.targets], dtype=np.complex128)
        return pos, amp

    def illumination(self, apc_ned: FloatArray, targets_ned: FloatArray) -> FloatArray:
        """Two-way antenna weight of each target at each pulse (rect beam).

        Stripmap: 1 where the target's angle from the plane normal to the antenna's array
        axis :attr:`beam_axis_ned`, ``asin(d . a / R)``, is within half the integration angle,
        else 0: the beam of the antenna fixed to the body at its steady attitude, squinted by
        the crab and the mount (see the module docstring). Spotlight: 1 everywhere.

        Parameters
        ----------
        apc_ned : ndarray, shape (P, 3)
            APC positions, NED, m.
        targets_ned : ndarray, shape (K, 3)
            Target positions, NED, m.

        Returns
        -------
        ndarray of float64, shape (P, K)
        """
        if self.mode == "spotlight":
            return np.ones((apc_ned.shape[0], targets_ned.shape[0]))
        d = targets_ned[None, :, :] - apc_ned[:, None, :]
        sin_off = (d @ self.beam_axis_ned) / np.linalg.norm(d, axis=-1)
        return (np.abs(sin_off) <= math.sin(self.integration_angle_rad / 2.0)).astype(float)


def scene_targets(scn: Scenario, n: int, rng: np.random.Generator) -> tuple[Target, ...]:
    """Random distributed scene: ``n`` scatterers with circular-Gaussian amplitudes.

    Positions are uniform on the ground over the swath (across track) and over the same extent
    along track, centred on the scene centre; amplitudes have unit mean power.

    Returns
    -------
    tuple of Target
        Positions in NED.
    """
    offset = np.zeros((n, 3))
    offset[:, :2] = (rng.random((n, 2)) - 0.5) * scn.swath_m
    pos = np.asarray(scn.scene_center_ned) + offset @ scn.track_to_ned.T
    amp = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / math.sqrt(2.0)
    return tuple(Target(_point(x), complex(a)) for x, a in zip(pos, amp, strict=True))


def level_track(
    t_s: FloatArray, start_m: float, speed_mps: float, altitude_m: float
) -> tuple[FloatArray, FloatArray]:
    """A straight, level, constant-speed track along x of a frame whose z points down.

    Parameters
    ----------
    t_s : ndarray of float64, shape (P,)
        Time since the first pulse, s.
    start_m : float
        x at ``t_s = 0``, m.
    speed_mps : float
        Speed along +x, m/s.
    altitude_m : float
        Height above z = 0 (the track lies at z = -altitude_m), m.

    Returns
    -------
    pos_m, vel_mps : ndarray of float64, shape (P, 3)
        Position (m) and velocity (m/s) in that frame.
    """
    t = np.asarray(t_s, dtype=np.float64)
    pos = np.zeros((t.size, 3))
    pos[:, 0] = start_m + speed_mps * t
    pos[:, 2] = -altitude_m
    vel = np.zeros((t.size, 3))
    vel[:, 0] = speed_mps
    return pos, vel


def radar_table(radar: RadarParams) -> dict[str, Any]:
    """The waveform and receiver keys of a configuration's ``radar`` table for ``radar``.

    Every :class:`RadarParams` field under its own name, in its own unit (Hz, s, samples):
    the keys of the daemon's ``[radar]`` section that describe the waveform, and the
    ``radar`` record of a run's truth. The link, sample format, channels and mode are
    the caller's.
    """
    return dataclasses.asdict(radar)


def _point(xyz: FloatArray) -> tuple[float, float, float]:
    return float(xyz[0]), float(xyz[1]), float(xyz[2])


def _track_to_ned(heading_rad: float, look_side: str) -> FloatArray:
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    mirror = 1.0 if look_side == "right" else -1.0
    return np.array([[c, -s * mirror, 0.0], [s, c * mirror, 0.0], [0.0, 0.0, 1.0]])


_RADAR_KEYS = {f.name for f in fields(RadarParams)}
_SCENARIO_KEYS = {f.name for f in fields(Scenario)} - {
    "radar",
    "name",
    "scale",
    "notes",
    "scene_center_ned",
    "clutter",
}
_PRESET_KEYS = {"azimuth_resolution_m", "beamwidth_rad"}


@dataclass(frozen=True, kw_only=True)
class PresetParams:
    """A preset's geometry and radar values, scaled, with :func:`load_preset`'s overrides.

    One field per override key (every :class:`RadarParams` field and every overridable
    :class:`Scenario` field), each holding the override where one is given. A value of None
    is derived by :func:`load_preset` from the others.

    Attributes
    ----------
    speed_mps : float
        Nominal ground speed along the track (track frame +x), m/s.
    altitude_m : float
        APC height above the flat ground (the track lies at track frame z = -altitude_m), m.
    center_slant_range_m : float
        Broadside slant range from the track to the scene centre, m.
    swath_m : float
        Ground-range extent of the scene, m, scaled; the preset's targets lie at fractions
        of it about the scene centre, along and across the track.
    mode : {"stripmap", "spotlight"}
        Beam mode (see :class:`Scenario`).
    snr_db : float or None
        Per-sample SNR of a unit target before compression, dB; None: no noise.
    t0_ns : int
        GPS time of the first pulse, ns.
    carrier_hz : float
        Centre (RF reference) frequency, Hz.
    bandwidth_hz : float
        Chirp bandwidth, Hz.
    pulse_width_s : float
        Chirp duration, s, scaled.
    sample_rate_hz : float
        Complex (I/Q) sample rate of the receiver, Hz.
    receive : {"matched", "dechirp"}
        Receive chain (see :class:`RadarParams`).
    chirp_direction : {"up", "down"}
        Sweep of the transmitted chirp.
    iq_conjugate : bool
        The receiver delivers the conjugate of the baseband I/Q.
    integration_angle_rad : float
        Azimuth angle spanned by the synthetic aperture (stripmap: the rect real beam), rad:
        the preset's, or its ``azimuth_resolution_m`` at the preset's carrier.
    prf_hz : float or None
        Pulse repetition frequency, Hz; None: the preset's, scaled, but not below
        :data:`PRF_OVERSAMPLING` times the targets' Doppler bandwidth.
    n_samples : int or None
        Complex samples per pulse; None: as many as the slant-range window needs. A preset's
        own count (scaled) stands while its receive chain is kept.
    range_gate_delay_s : float or None
        Two-way delay from the pulse time stamp to the first sample (matched) or to the
        dechirp reference (dechirp), s; None: from the slant-range window.
    aperture_s : float or None
        Duration of the targets' aperture, s (``approach_s`` not included); None: from the
        integration angle and the targets.
    track_start_north_m : float or None
        Along-track position (track frame x) of the nominal APC at the first pulse of the
        targets' aperture, m; None: placed so that the targets cross the beam centre
        about mid-aperture.
    targets : sequence of Target or None
        Point scatterers, positions in the track frame (x along the track, y toward the
        look side, z down), m; None: the preset's.
    heading_rad, look_side, lever_arm_m, crab_rad, antenna_squint_rad
        The track's heading, the look side, the lever arm, the crab and the mount's squint:
        :class:`Scenario`'s fields of those names, in its units and frames.
    """

    speed_mps: float
    altitude_m: float
    center_slant_range_m: float
    swath_m: float
    mode: Literal["stripmap", "spotlight"]
    snr_db: float | None
    t0_ns: int = DEFAULT_T0_NS
    carrier_hz: float
    bandwidth_hz: float
    pulse_width_s: float
    sample_rate_hz: float
    receive: Literal["matched", "dechirp"]
    chirp_direction: Literal["up", "down"]
    iq_conjugate: bool
    integration_angle_rad: float
    prf_hz: float | None = None
    n_samples: int | None = None
    range_gate_delay_s: float | None = None
    aperture_s: float | None = None
    track_start_north_m: float | None = None
    targets: Sequence[Target] | None = None
    heading_rad: float = 0.0
    look_side: Literal["right", "left"] = "right"
    lever_arm_m: tuple[float, float, float] = DEFAULT_LEVER_ARM_M
    crab_rad: float = 0.0
    antenna_squint_rad: float = 0.0


def _read_preset(name: str) -> dict[str, Any]:
    if name not in PRESETS:
        raise ConfigError(f"scenario: {name!r} is not one of {', '.join(PRESETS)}")
    text = resources.files("sarmoco.sim").joinpath("presets", f"{name}.toml").read_text()
    return tomllib.loads(text)


def _integration_angle(raw: dict[str, Any], wavelength_m: float) -> float:
    if "integration_angle_rad" in raw:
        return float(raw["integration_angle_rad"])
    if "azimuth_resolution_m" in raw:
        return 2.0 * math.asin(wavelength_m / (4.0 * float(raw["azimuth_resolution_m"])))
    raise ConfigError(
        "scenario: preset gives neither integration_angle_rad nor azimuth_resolution_m"
    )


def _aperture_s(p: PresetParams, targets_ned: FloatArray, ground_centre_m: float) -> float:
    if p.mode == "spotlight":
        half = math.tan(p.integration_angle_rad / 2.0)
        r_c = math.hypot(ground_centre_m, p.altitude_m)
        return 2.0 * r_c * half / p.speed_mps
    lo, hi = _lit_track_interval(p, targets_ned)
    return 1.02 * float(np.max(hi) - np.min(lo)) / p.speed_mps


def _track_start(p: PresetParams, targets_ned: FloatArray, aperture_s: float) -> float:
    if p.mode == "spotlight":
        centre = targets_ned[:, 0]
    else:
        centre = targets_ned[:, 0] - _beam_geometry(p, targets_ned)[0]
    mid = 0.5 * float(np.min(centre) + np.max(centre))
    return mid - 0.5 * p.speed_mps * aperture_s


def _beam_squint(antenna_squint_rad: float, crab_rad: float, look_side: str) -> float:
    """The beam's squint from the track's broadside, rad, positive forward."""
    return antenna_squint_rad - (crab_rad if look_side == "right" else -crab_rad)


def _beam_geometry(p: PresetParams, targets_ned: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per target (track frame), the along-track offset from the platform to the target at
    the beam centre crossing, and the half-length of the track that lights it, m.

    For a level straight track at ``-altitude_m`` and a beam cone about the array axis
    ``(cos psi, -sin psi, 0)`` (``psi`` the beam squint), a target at (x, y, z) is lit from
    the platform at ``x - u`` while ``(u cos psi - y sin psi)**2 <= S**2 (u**2 + rho**2)``
    (``S`` the sine of half the integration angle, ``rho`` the target's broadside range):
    ``u`` between ``c -+ w`` with ``c = y sin psi cos psi / (cos**2 psi - S**2)`` and
    ``w = S sqrt(rho**2 (cos**2 psi - S**2) + y**2 sin**2 psi) / (cos**2 psi - S**2)``.
    """
    psi = _beam_squint(p.antenna_squint_rad, p.crab_rad, p.look_side)
    sin_half = math.sin(p.integration_angle_rad / 2.0)
    cos2 = math.cos(psi) ** 2 - sin_half**2
    y = targets_ned[:, 1]
    rho = np.hypot(y, targets_ned[:, 2] + p.altitude_m)
    centre = y * (math.sin(psi) * math.cos(psi) / cos2)
    half = sin_half * np.sqrt(rho**2 * cos2 + (y * math.sin(psi)) ** 2) / cos2
    return centre, half


def _lit_track_interval(p: PresetParams, targets_ned: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Along-track platform positions [first, last] that light each target (stripmap), m."""
    centre, half = _beam_geometry(p, targets_ned)
    x = targets_ned[:, 0] - centre
    return x - half, x + half


def _doppler_bandwidth_hz(
    p: PresetParams, targets_ned: FloatArray, wavelength_m: float, track_m: tuple[float, float]
) -> float:
    """Two-sided Doppler bandwidth of all targets over the aperture, Hz.

    ``track_m`` holds the along-track positions (track frame x) of the nominal APC at the
    aperture's first and last pulse, m.
    """
    if p.mode == "stripmap":
        return 4.0 * p.speed_mps * math.sin(p.integration_angle_rad / 2.0) / wavelength_m
    sins = []
    for x_apc in track_m:
        d = targets_ned - np.array([x_apc, 0.0, -p.altitude_m])
        sins.append(d[:, 0] / np.linalg.norm(d, axis=1))
    s = np.concatenate(sins)
    return 2.0 * p.speed_mps * float(s.max() - s.min()) / wavelength_m


def _slant_window_m(
    p: PresetParams, targets_ned: FloatArray, ground_centre_m: float, track_m: tuple[float, float]
) -> tuple[float, float]:
    """Slant-range interval [near, far] the receive window must hold, m (``track_m`` as for
    :func:`_doppler_bandwidth_hz`)."""
    h = p.altitude_m
    edges = np.array([ground_centre_m - p.swath_m / 2.0, ground_centre_m + p.swath_m / 2.0])
    ranges = [np.hypot(np.maximum(edges, 0.0), h)]
    for x_apc in track_m:
        d = targets_ned - np.array([x_apc, 0.0, -h])
        ranges.append(np.linalg.norm(d, axis=1))
    ranges.append(np.hypot(targets_ned[:, 1], targets_ned[:, 2] + h))
    r = np.concatenate(ranges)
    margin = RANGE_MARGIN_FRACTION * float(r.max() - r.min()) + RANGE_MARGIN_M
    return float(r.min()) - margin, float(r.max()) + margin


def _receiver(p: PresetParams, near_m: float, far_m: float, r_c: float) -> tuple[int, float]:
    """n_samples and range_gate_delay_s for the receive chain (explicit values win)."""
    fs, tp = p.sample_rate_hz, p.pulse_width_s
    if p.receive == "matched":
        if fs < p.bandwidth_hz:
            raise ConfigError(
                f"scenario.sample_rate_hz: {fs!r} is below the bandwidth {p.bandwidth_hz!r} "
                "(matched-filter receive samples the whole chirp)"
            )
        gate = 2.0 * near_m / C_MPS if p.range_gate_delay_s is None else p.range_gate_delay_s
        record_s = 2.0 * (far_m - near_m) / C_MPS + tp
        n = 2 * math.ceil(record_s * fs / 2.0) if p.n_samples is None else p.n_samples
        return int(n), float(gate)
    gate = 2.0 * r_c / C_MPS if p.range_gate_delay_s is None else p.range_gate_delay_s
    ref_m = C_MPS * gate / 2.0
    max_dev_s = 2.0 * max(ref_m - near_m, far_m - ref_m) / C_MPS
    record_s = tp + 2.0 * max_dev_s
    n = int(2 * math.ceil(record_s * fs / 2.0) if p.n_samples is None else p.n_samples)
    chirp_rate = p.bandwidth_hz / tp
    half_window_s = min((n / fs - tp) / 2.0, fs / (2.0 * chirp_rate))
    if half_window_s < max_dev_s:
        raise ConfigError(
            f"scenario.receive: dechirp window +-{C_MPS * half_window_s / 2:.2f} m about "
            f"{ref_m:.2f} m does not hold the scene ({near_m:.2f} .. {far_m:.2f} m); "
            "raise n_samples or sample_rate_hz"
        )
    return n, float(gate)


def load_preset(
    name: str, scale: float = 1.0, approach_s: float = 0.0, **overrides: Any
) -> Scenario:
    """Load a shipped scenario preset.

    Parameters
    ----------
    name : str
        One of :data:`PRESETS`.
    scale : float
        0 < scale <= 1: shrinks swath, pulse width (samples) and PRF, keeping the resolutions.
    approach_s : float
        Straight flight before the targets' aperture, s (>= 0): the track starts
        ``approach_s * speed_mps`` earlier and the run lasts ``approach_s`` longer; the
        receive window, PRF and targets stay the preset's (the targets then come into the
        beam ``approach_s`` after the first pulse).
    **overrides
        Any :class:`RadarParams` field (e.g. ``prf_hz``, ``receive``, ``n_samples``,
        ``chirp_direction``, ``iq_conjugate``) or
        :class:`Scenario` field (e.g. ``snr_db``, ``targets``, ``aperture_s``, ``mode``,
        ``crab_rad``, ``antenna_squint_rad``),
        applied after scaling; derived values (range gate, samples, aperture) follow them
        unless given themselves.

    Returns
    -------
    Scenario

    Raises
    ------
    ConfigError
        Unknown preset or override key, bad scale, a geometry the receiver cannot hold.
    """
    if not 0.0 < scale <= 1.0:
        raise ConfigError(f"scenario.scale: {scale!r} is not in (0, 1]")
    unknown = set(overrides) - _RADAR_KEYS - _SCENARIO_KEYS
    if unknown:
        raise ConfigError(f"scenario: unknown override(s) {sorted(unknown)}")
    raw = _read_preset(name)
    p = _preset_params(raw, scale, overrides)
    if p.center_slant_range_m <= p.altitude_m:
        raise ConfigError(
            f"scenario.center_slant_range_m: {p.center_slant_range_m} is not > altitude "
            f"{p.altitude_m}"
        )
    ground_c = math.sqrt(p.center_slant_range_m**2 - p.altitude_m**2)
    p = _orientation(p)
    targets = _targets(p, raw.get("targets", {}), ground_c)
    t_ned = np.array([t.pos_ned for t in targets], dtype=np.float64).reshape(-1, 3)
    aperture_s = p.aperture_s
    if aperture_s is None:
        aperture_s = _aperture_s(p, t_ned, ground_c)
    start_m = p.track_start_north_m
    if start_m is None:
        start_m = _track_start(p, t_ned, aperture_s)
    track_m = (start_m, start_m + p.speed_mps * aperture_s)
    radar, (near, far) = _radar(p, float(raw["radar"]["prf_hz"]), scale, t_ned, ground_c, track_m)
    if not approach_s >= 0.0:
        raise ConfigError(f"scenario.approach_s: {approach_s!r} is not >= 0")
    rot = _track_to_ned(p.heading_rad, p.look_side)
    notes = {k: float(raw[k]) for k in _PRESET_KEYS if k in raw}
    notes["slant_window_near_m"], notes["slant_window_far_m"] = near, far
    return Scenario(
        name=name,
        radar=radar,
        speed_mps=p.speed_mps,
        altitude_m=p.altitude_m,
        center_slant_range_m=p.center_slant_range_m,
        swath_m=p.swath_m,
        mode=p.mode,
        aperture_s=float(aperture_s + approach_s),
        targets=tuple(Target(_point(rot @ np.asarray(t.pos_ned)), t.amplitude) for t in targets),
        snr_db=None if p.snr_db is None else float(p.snr_db),
        scale=scale,
        scene_center_ned=(float(rot[0, 1] * ground_c), float(rot[1, 1] * ground_c), 0.0),
        integration_angle_rad=float(p.integration_angle_rad),
        track_start_north_m=float(start_m - approach_s * p.speed_mps),
        t0_ns=int(p.t0_ns),
        heading_rad=p.heading_rad,
        look_side=p.look_side,
        lever_arm_m=p.lever_arm_m,
        crab_rad=p.crab_rad,
        antenna_squint_rad=p.antenna_squint_rad,
        notes=notes,
    )


def _preset_params(raw: dict[str, Any], scale: float, overrides: dict[str, Any]) -> PresetParams:
    """The preset's geometry and radar values, scaled, overrides applied.

    The preset's ``n_samples`` is kept (scaled) only while the receive chain is its own.
    """
    radar_raw = raw["radar"]
    carrier_hz = float(radar_raw["carrier_hz"])
    p = PresetParams(
        speed_mps=float(raw["speed_mps"]),
        altitude_m=float(raw["altitude_m"]),
        center_slant_range_m=float(raw["center_slant_range_m"]),
        swath_m=float(raw["swath_m"]) * scale,
        mode=raw["mode"],
        snr_db=raw.get("snr_db"),
        carrier_hz=carrier_hz,
        bandwidth_hz=float(radar_raw["bandwidth_hz"]),
        pulse_width_s=float(radar_raw["pulse_width_s"]) * scale,
        sample_rate_hz=float(radar_raw["sample_rate_hz"]),
        receive=radar_raw["receive"],
        chirp_direction=radar_raw.get("chirp_direction", "up"),
        iq_conjugate=radar_raw.get("iq_conjugate", False),
        integration_angle_rad=_integration_angle(raw, C_MPS / carrier_hz),
    )
    p = dataclasses.replace(p, **overrides)
    if "n_samples" in radar_raw and p.n_samples is None and p.receive == radar_raw["receive"]:
        p = dataclasses.replace(p, n_samples=2 * round(int(radar_raw["n_samples"]) * scale / 2.0))
    if p.mode not in ("stripmap", "spotlight"):
        raise ConfigError(f"scenario.mode: {p.mode!r} is not 'stripmap' or 'spotlight'")
    return p


def _targets(p: PresetParams, fractions: dict[str, Any], ground_c: float) -> tuple[Target, ...]:
    """The override's targets, or the preset's (fractions of the swath about the scene
    centre at ground range ``ground_c``, m), in the track frame."""
    if p.targets is not None:
        targets = tuple(p.targets)
    else:
        targets = tuple(
            Target((fn * p.swath_m, ground_c + fe * p.swath_m, 0.0))
            for fn, fe in zip(fractions["north_frac"], fractions["east_frac"], strict=True)
        )
    if not targets:
        raise ConfigError("scenario.targets: empty")
    return targets


def _radar(
    p: PresetParams,
    full_prf_hz: float,
    scale: float,
    targets_ned: FloatArray,
    ground_c: float,
    track_m: tuple[float, float],
) -> tuple[RadarParams, tuple[float, float]]:
    """The radar parameters and the slant window [near, far] (m) they receive (``track_m``
    as for :func:`_doppler_bandwidth_hz`).

    The PRF, unless given, is the preset's scaled down but not below
    :data:`PRF_OVERSAMPLING` times the targets' Doppler bandwidth; the gate and sample
    count follow the window (:func:`_receiver`).
    """
    prf_hz = p.prf_hz
    if prf_hz is None:
        wavelength_m = C_MPS / p.carrier_hz
        floor = PRF_OVERSAMPLING * _doppler_bandwidth_hz(p, targets_ned, wavelength_m, track_m)
        prf_hz = max(full_prf_hz * scale, min(full_prf_hz, floor))
    near, far = _slant_window_m(p, targets_ned, ground_c, track_m)
    n_samples, gate = _receiver(p, near, far, p.center_slant_range_m)
    radar = RadarParams(
        carrier_hz=p.carrier_hz,
        bandwidth_hz=p.bandwidth_hz,
        pulse_width_s=p.pulse_width_s,
        sample_rate_hz=p.sample_rate_hz,
        prf_hz=prf_hz,
        n_samples=n_samples,
        range_gate_delay_s=gate,
        receive=p.receive,
        chirp_direction=p.chirp_direction,
        iq_conjugate=p.iq_conjugate,
    )
    return radar, (near, far)


def _orientation(p: PresetParams) -> PresetParams:
    """``p`` with its orientation checked and its heading, lever arm, crab and mount squint
    made floats (overrides may give ints, or a list for the lever arm).

    The look side must be "right" or "left", the lever arm 3 numbers, and the beam's
    squint plus half the integration angle below 90 degrees.
    """
    if p.look_side not in ("right", "left"):
        raise ConfigError(f"scenario.look_side: {p.look_side!r} is not 'right' or 'left'")
    lever = tuple(float(v) for v in p.lever_arm_m)
    if len(lever) != 3:
        raise ConfigError(f"scenario.lever_arm_m: {p.lever_arm_m!r} is not 3 numbers")
    crab, squint = float(p.crab_rad), float(p.antenna_squint_rad)
    psi = _beam_squint(squint, crab, p.look_side)
    if not abs(psi) + p.integration_angle_rad / 2.0 < math.pi / 2.0:
        raise ConfigError(
            f"scenario.crab_rad/antenna_squint_rad: {crab!r}/{squint!r} "
            f"squint the beam by {math.degrees(psi):.1f} deg, past the horizon"
        )
    return dataclasses.replace(
        p,
        heading_rad=float(p.heading_rad),
        lever_arm_m=_point(np.asarray(lever)),
        crab_rad=crab,
        antenna_squint_rad=squint,
    )
