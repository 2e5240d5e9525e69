"""Survey-pattern flight: straight legs joined by banked 180° turns, targets along every leg.

The pattern is a lawnmower flown away from the look side: leg 0 along the scenario's
heading, then a coordinated turn away from the illuminated side onto the reverse
heading two turn radii over, leg 1, a turn the other way, leg 2 parallel to leg 0 four
radii over, and so on; every leg images new ground at the scenario's scene-centre range
on its own look side. All geometry is in the heading frame (x forward along leg 0,
y right, z down; :meth:`Scenario.heading_to_ned` takes it to NED).

Turn and turbulence numbers are measured from the real ArduPilot telemetry log
``../shared/data/mavlink/arduplane_quadplane_sitl.tlog`` (a QuadPlane's fixed-wing
loiters; ATTITUDE and LOCAL_POSITION_NED messages at 4 Hz):

- turn rate :data:`LOG_TURN_RATE_DPS` = 11.6 °/s (ATTITUDE yawspeed over the first loiter,
  45-72 s after the log's start, 11.6 ± 1.0 °/s) at 14.4 m/s with 18.0 ± 0.2° of bank,
  i.e. a coordinated turn (atan(v ω / g) = 16.6°). The survey flies that turn rate at
  the scenario's speed with the coordinated bank atan(v ω / g) (ku-vehicle, 17.5 m/s:
  19.9°, radius 86 m). The log's second loiter (26.7 m/s, 14.8 °/s, 46° bank) is the
  same relation at a higher speed.
- along-leg turbulence (:func:`survey_spec`): ground-speed wander about its trend
  :data:`LOG_SPEED_RMS_MPS` = 0.35 m/s rms (first loiter; 0.20 m/s in the second),
  vertical wander :data:`LOG_VERTICAL_RMS_M` = 0.20 m rms, cross-track wander
  :data:`LOG_CROSS_RMS_M` = 0.15 m rms (radial distance about the fitted circle of the
  steady second loiter). The vertical figure matches the log's vertical *velocity*
  wander in the steady loiter, 0.25 m/s rms, through the model's velocity/displacement
  ratio (1.27 /s at its 0.2 Hz corner); the log's altitude wander about a linear trend
  (0.54 m rms over that 19 s, 1.40 m in the first loiter, which still climbs) is mostly
  slower than the model's band, and taken as displacement it would give the model
  2.7 times the log's vertical velocity. The log has no straight leg long enough to
  measure on one; these drive the seeded turbulence model of
  :mod:`sarmoco.sim.trajectory` (second-order spectrum, corner 0.2 Hz) along the whole
  flight, rotated with the heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from sarmoco.errors import ConfigError
from sarmoco.processing.types import FloatArray
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.scenario import Scenario, Target
from sarmoco.sim.turbulence import TurbulenceDeviation

G_MPS2 = 9.80665
"""Standard gravity, m/s²."""
LOG_TURN_RATE_DPS = 11.6
"""Turn rate of the real log's loiter, °/s (see the module docstring)."""
LOG_SPEED_RMS_MPS = 0.35
"""Ground-speed wander of the real log about its trend, m/s rms."""
LOG_VERTICAL_RMS_M = 0.20
"""Vertical wander giving the real log's vertical velocity wander (0.25 m/s rms), m rms."""
LOG_CROSS_RMS_M = 0.15
"""Radial wander of the real log's steady loiter about its circle, m rms."""
ROLL_IN_S = 1.0
"""The bank builds up (and goes back to level) over this time, centred on a turn's start
(end), with a smooth step (C1), s. Chosen, not measured: the log's 4 Hz ATTITUDE does not
resolve its roll-ins. An instantaneous bank would move the lever-armed antenna by
centimetres in no time."""


def survey_spec(
    legs: int = 2, leg_s: float = 20.0, seed: int = 0, turn_rate_dps: float | None = None
) -> MotionSpec:
    """A ``survey`` motion with the turbulence measured from the real log.

    Parameters
    ----------
    legs : int
        Straight legs (>= 1), joined by ``legs - 1`` turns.
    leg_s : float
        Duration of each straight leg, s.
    seed : int
        Seed of the turbulence.
    turn_rate_dps : float or None
        Turn rate between legs, deg/s (None: the real log's, :data:`LOG_TURN_RATE_DPS`).
    """
    return MotionSpec(
        kind="survey",
        cross_track_rms_m=LOG_CROSS_RMS_M,
        vertical_rms_m=LOG_VERTICAL_RMS_M,
        along_speed_rms_mps=LOG_SPEED_RMS_MPS,
        seed=seed,
        legs=legs,
        leg_s=leg_s,
        turn_rate_dps=turn_rate_dps,
    )


@dataclass(frozen=True)
class SurveyPattern:
    """Timing and geometry of the legs and turns (heading frame, relative to the start).

    Parameters
    ----------
    speed_mps : float
        Ground speed, m/s.
    legs : int
        Number of straight legs.
    leg_s : float
        Duration of each leg, s.
    turn_rate_rps : float
        Turn rate, rad/s (positive).
    first_turn : {-1, 1}
        Sign of the first turn's heading rate (-1: to the left), away from the look side.
    """

    speed_mps: float
    legs: int
    leg_s: float
    turn_rate_rps: float
    first_turn: int

    @classmethod
    def of(cls, scn: Scenario, spec: MotionSpec) -> SurveyPattern:
        """The pattern a ``survey`` spec flies for a scenario (turn away from its look side)."""
        rate_dps = LOG_TURN_RATE_DPS if spec.turn_rate_dps is None else spec.turn_rate_dps
        if spec.legs < 1 or not spec.leg_s > 0.0 or not 0.0 < rate_dps < 90.0:
            raise ConfigError(
                f"motion: survey needs legs >= 1, leg_s > 0 and a turn rate in (0, 90) deg/s "
                f"(got {spec.legs}, {spec.leg_s}, {rate_dps})"
            )
        return cls(
            speed_mps=scn.speed_mps,
            legs=spec.legs,
            leg_s=spec.leg_s,
            turn_rate_rps=math.radians(rate_dps),
            first_turn=-1 if scn.look_side == "right" else 1,
        )

    @property
    def turn_s(self) -> float:
        """Duration of one 180° turn, s."""
        return math.pi / self.turn_rate_rps

    @property
    def radius_m(self) -> float:
        """Turn radius v / ω, m."""
        return self.speed_mps / self.turn_rate_rps

    @property
    def bank_rad(self) -> float:
        """Coordinated-turn bank atan(v ω / g), rad."""
        return math.atan(self.speed_mps * self.turn_rate_rps / G_MPS2)

    @property
    def duration_s(self) -> float:
        """Legs and turns, s."""
        return self.legs * self.leg_s + (self.legs - 1) * self.turn_s

    def leg_start_s(self, leg: int) -> float:
        """Time the straight leg ``leg`` starts, s."""
        return leg * (self.leg_s + self.turn_s)

    def _piece(self, t: FloatArray) -> tuple[np.ndarray, FloatArray, np.ndarray]:
        """Index of the leg each time belongs to (turns to the leg before), time into the
        piece (s) and whether it is in a turn."""
        period = self.leg_s + self.turn_s
        k = np.clip(np.floor(t / period), 0, self.legs - 1).astype(int)
        into = t - k * period
        turning = (into > self.leg_s) & (k < self.legs - 1)
        return k, into, turning

    def heading(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Heading (rad, from x toward y) and heading rate (rad/s) at ``t_s``."""
        k, into, turning = self._piece(np.asarray(t_s, dtype=np.float64))
        sign = self.first_turn * np.where(k % 2 == 0, 1.0, -1.0)
        base = np.where(k % 2 == 0, 0.0, math.pi)
        tau = np.where(turning, into - self.leg_s, 0.0)
        psi = base + sign * self.turn_rate_rps * tau
        return psi, np.where(turning, sign * self.turn_rate_rps, 0.0)

    def bank(self, t_s: FloatArray) -> FloatArray:
        """Roll angle, rad: the coordinated bank in turns, eased in and out over
        :data:`ROLL_IN_S` (positive: right wing down, a right turn)."""
        t = np.asarray(t_s, dtype=np.float64)
        k = self._piece(t)[0]
        out = np.zeros_like(t)
        for j in (k - 1, k):  # the turn after the previous leg and after this one
            start = j * (self.leg_s + self.turn_s) + self.leg_s
            w = _smooth_step((t - start) / ROLL_IN_S + 0.5) * _smooth_step(
                (start + self.turn_s - t) / ROLL_IN_S + 0.5
            )
            valid = (j >= 0) & (j < self.legs - 1)
            sign = self.first_turn * np.where(j % 2 == 0, 1.0, -1.0)
            out += np.where(valid, sign * w * self.bank_rad, 0.0)
        return out

    def path(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Horizontal position (m), velocity (m/s), acceleration (m/s²) of the pattern,
        heading frame (x, y), position 0 at t = 0; each (P, 2)."""
        t = np.asarray(t_s, dtype=np.float64)
        k, into, turning = self._piece(t)
        v, w, r = self.speed_mps, self.turn_rate_rps, self.radius_m
        psi, rate = self.heading(t)
        # leg k starts at x = 0 (odd legs: at the far end, x = v leg_s), y = 2 r k across
        forward = np.where(k % 2 == 0, 1.0, -1.0)
        start = np.stack(
            [np.where(k % 2 == 0, 0.0, v * self.leg_s), self.first_turn * 2.0 * r * k], axis=1
        )
        along = np.where(k == self.legs - 1, into, np.minimum(into, self.leg_s))  # last: on
        pos = start + np.stack([forward * v * along, np.zeros_like(t)], axis=1)
        # in a turn: arc from the leg's end, heading psi0 = base, signed rate s w
        psi0 = np.where(k % 2 == 0, 0.0, math.pi)
        s = np.where(rate != 0.0, np.sign(rate), 1.0)
        arc = np.stack(
            [(np.sin(psi) - np.sin(psi0)) / (s * w), -(np.cos(psi) - np.cos(psi0)) / (s * w)],
            axis=1,
        )
        pos = pos + np.where(turning[:, None], v * arc, 0.0)
        vel = v * np.stack([np.cos(psi), np.sin(psi)], axis=1)
        acc = v * rate[:, None] * np.stack([-np.sin(psi), np.cos(psi)], axis=1)
        return pos, vel, acc

    def targets(self, scn: Scenario, per_leg: int, margin_s: float) -> tuple[Target, ...]:
        """Point targets on the ground at broadside of every leg, NED.

        Parameters
        ----------
        scn : Scenario
            Altitude, scene-centre range, heading and look side.
        per_leg : int
            Targets per leg, evenly spread.
        margin_s : float
            No target's broadside time is closer than this to a leg's ends, s.
        """
        if self.leg_s <= 2.0 * margin_s:
            raise ConfigError(f"survey: legs of {self.leg_s} s leave no room inside {margin_s} s")
        ground = math.sqrt(scn.center_slant_range_m**2 - scn.altitude_m**2)
        look = 1.0 if scn.look_side == "right" else -1.0
        frac = (np.arange(per_leg) + 0.5) / per_leg
        out = []
        for leg in range(self.legs):
            t_b = self.leg_start_s(leg) + margin_s + frac * (self.leg_s - 2.0 * margin_s)
            pos, vel, _ = self.path(t_b)
            right = np.stack([-vel[:, 1], vel[:, 0]], axis=1) / self.speed_mps
            xy = pos + look * ground * right
            start = np.array([scn.track_start_north_m, 0.0, 0.0])
            for x, y in xy:
                ned = scn.heading_to_ned @ (start + np.array([x, y, 0.0]))
                out.append(Target((float(ned[0]), float(ned[1]), 0.0)))
        return tuple(out)


def _smooth_step(x: FloatArray) -> FloatArray:
    """0 below 0, 1 above 1, 3x² - 2x³ between."""
    c = np.clip(x, 0.0, 1.0)
    return np.asarray(c * c * (3.0 - 2.0 * c), dtype=np.float64)


class SurveyDeviation:
    """The survey pattern as a deviation from the scenario's straight nominal line.

    Position, velocity, acceleration (heading frame) of the pattern plus the seeded
    turbulence of the spec rotated into the current heading (so the along-track,
    cross-track and vertical wander follow the legs), minus the nominal line; roll is
    the coordinated bank in turns (:meth:`SurveyPattern.bank`) plus the turbulence's,
    yaw the heading.
    """

    def __init__(self, scn: Scenario, spec: MotionSpec) -> None:
        self.pattern = SurveyPattern.of(scn, spec)
        self.turbulence = TurbulenceDeviation(spec)

    def __call__(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Position, velocity, acceleration deviations (P, 3) and Euler angles (P, 3)."""
        t = np.asarray(t_s, dtype=np.float64)
        pat = self.pattern
        dp, dv, da, euler = self.turbulence(t)
        psi, rate = pat.heading(t)
        c, s = np.cos(psi), np.sin(psi)

        def rot(a: FloatArray) -> FloatArray:  # R(psi) a
            return np.stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1]], axis=1)

        def rot_rate(a: FloatArray) -> FloatArray:  # dR/dpsi a
            return np.stack([-s * a[:, 0] - c * a[:, 1], c * a[:, 0] - s * a[:, 1]], axis=1)

        pos_xy, vel_xy, acc_xy = pat.path(t)
        w = rate[:, None]
        pos, vel, acc = (np.empty((t.size, 3)) for _ in range(3))
        pos[:, :2] = pos_xy + rot(dp[:, :2])
        vel[:, :2] = vel_xy + rot(dv[:, :2]) + w * rot_rate(dp[:, :2])
        acc[:, :2] = acc_xy + rot(da[:, :2]) + 2 * w * rot_rate(dv[:, :2]) - w**2 * rot(dp[:, :2])
        pos[:, 2], vel[:, 2], acc[:, 2] = dp[:, 2], dv[:, 2], da[:, 2]
        pos[:, 0] -= pat.speed_mps * t  # the nominal line the trajectory adds back
        vel[:, 0] -= pat.speed_mps
        euler = euler + np.stack([pat.bank(t), np.zeros_like(t), psi], axis=1)
        return pos, vel, acc, euler


def leg_times_ns(scn: Scenario, spec: MotionSpec) -> list[tuple[int, int]]:
    """Start and end of each straight leg of the survey ``spec`` flies for ``scn``, GPS ns
    (the trajectory's time 0 is the first pulse, ``scn.t0_ns``)."""
    pat = SurveyPattern.of(scn, spec)
    return [
        (scn.t0_ns + round(t * 1e9), scn.t0_ns + round((t + pat.leg_s) * 1e9))
        for t in (pat.leg_start_s(k) for k in range(pat.legs))
    ]


def survey_scenario(
    base: Scenario, spec: MotionSpec, per_leg: int = 2, margin_s: float | None = None
) -> Scenario:
    """``base`` flown as the survey of ``spec``, with targets along every leg.

    The receive window, PRF and radar are the base scenario's (its scene-centre range is
    where every leg's targets lie); the run lasts the whole pattern.

    Parameters
    ----------
    base : Scenario
        A stripmap preset (e.g. ``load_preset("ku-vehicle", 0.1)``).
    spec : MotionSpec
        A ``survey`` motion (:func:`survey_spec`).
    per_leg : int
        Targets per leg.
    margin_s : float or None
        No target closer to a leg's end than this, s; None: 2.5 synthetic apertures
        (a target's aperture then ends well before the next turn is flagged, and starts
        after the last one's flag has cleared).
    """
    if base.mode != "stripmap":
        raise ConfigError(f"survey: scenario mode {base.mode!r} is not 'stripmap'")
    pattern = SurveyPattern.of(base, spec)
    if margin_s is None:
        aperture_s = base.center_slant_range_m * base.integration_angle_rad / base.speed_mps
        margin_s = 2.5 * aperture_s
    targets = pattern.targets(base, per_leg, margin_s)
    return replace(base, targets=targets, aperture_s=pattern.duration_s)
