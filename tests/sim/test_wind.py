"""A platform in a crosswind: the body crabs, the beam fixed to it squints, the INS reports it.

The echoes light each target while it crosses the broadside of the *body* (yawed from the
ground track by the crab), not the track's; the attitude on every INS wire (MAVLink
ATTITUDE_QUATERNION, SBG EKF_QUAT and EKF_EULER, SBG CAN quaternion and Euler) differs from
the course of the velocity on the same wire by the crab. Both look sides, crabs of -15 to
+15 degrees.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from scipy.spatial.transform import Rotation

from sarmoco.app.simcommand import platform_arguments, scenario_overrides
from sarmoco.drivers.can_source import CanLogSource
from sarmoco.drivers.samples import AttitudeSample, Sample, VelocitySample
from sarmoco.drivers.sbg import SbgFileSource
from sarmoco.drivers.source import Source
from sarmoco.errors import ConfigError
from sarmoco.processing.rangecomp import compress
from sarmoco.sim.emit_can import SbgCanEmitter
from sarmoco.sim.emit_sbg import SbgEmitter
from sarmoco.sim.emitter import Emitter
from sarmoco.sim.faults import Faults
from sarmoco.sim.insemitters import INS_EMITTERS, InsEmitterOptions
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import Target, load_preset
from sarmoco.sim.transports import FileLink
from tests.daemon.test_end_to_end import assert_focused, store_points
from tests.sim.emit_common import play_fast

HEADING_DEG = 62.0
"""Track heading of every case (no axis of NED lines up with the track)."""

CRABS_DEG = (-15.0, -10.0, -4.0, 4.0, 10.0, 15.0)
SIDES = ("right", "left")


def _yaw_rad(quat_wxyz: np.ndarray) -> np.ndarray:
    """3-2-1 yaw of body-to-NED quaternions (scalar first), rad."""
    return Rotation.from_quat(np.asarray(quat_wxyz)[:, [1, 2, 3, 0]]).as_euler("ZYX")[:, 0]


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * a))


@pytest.mark.parametrize("side", SIDES)
@pytest.mark.parametrize("crab_deg", CRABS_DEG)
def test_echoes_light_a_target_about_the_body_broadside(crab_deg: float, side: str) -> None:
    """A target's echoes begin and end where it is half the integration angle ahead of and
    behind the body's broadside (the plane normal to body x, from the true attitude): the beam
    is centred on the body's broadside, not the track's."""
    base = load_preset("ku-vehicle", scale=0.1)
    ground = math.sqrt(base.center_slant_range_m**2 - base.altitude_m**2)
    scn = load_preset(
        "ku-vehicle", scale=0.1, heading_rad=math.radians(HEADING_DEG), look_side=side,
        crab_rad=math.radians(crab_deg), snr_db=None, targets=(Target((0.0, ground, 0.0)),),
    )  # fmt: skip
    run = simulate(scn, MotionSpec("ideal"), "ideal")
    lit = np.flatnonzero(np.abs(np.asarray(run.echo)).sum(axis=1) > 0)
    assert lit.size > 0 and 0 < lit[0] and lit[-1] < run.t_ns.size - 1  # a whole crossing
    assert np.all(np.diff(lit) == 1)
    body_x = Rotation.from_quat(run.traj.quat[:, [1, 2, 3, 0]]).apply([1.0, 0.0, 0.0])
    d = run.targets_ned[0] - run.apc_ned
    ahead = np.arcsin(np.sum(d * body_x, axis=1) / np.linalg.norm(d, axis=1))
    half = scn.integration_angle_rad / 2.0
    assert ahead[lit[0] - 1] > half >= ahead[lit[0]]
    assert ahead[lit[-1]] >= -half > ahead[lit[-1] + 1]
    body_broadside = int(np.searchsorted(-ahead, 0.0))
    # the track's broadside is the crab's lever (ground range x tan crab) away, on the side
    # the crab turns the beam to: aft looking right with a positive crab, forward looking left
    track_x = run.vel_ned[0] / np.linalg.norm(run.vel_ned[0])
    along = float(d[int(body_broadside)] @ track_x)
    toward = -math.copysign(1.0, crab_deg) * (1.0 if side == "right" else -1.0)
    assert along * toward == pytest.approx(ground * math.tan(math.radians(abs(crab_deg))), rel=0.01)


def _drain(src: Source) -> list[Sample]:
    out: list[Sample] = []
    while not src.eof:
        out += src.poll()
    return out


@pytest.fixture(scope="module")
def crabbed_runs() -> dict[tuple[float, str], SimRun]:
    """A few pulses of a crabbed ku-vehicle run per crab and look side (straight and level,
    tactical INS)."""
    runs = {}
    for crab in (-15.0, 10.0):
        for side in SIDES:
            scn = load_preset(
                "ku-vehicle", scale=0.1, heading_rad=math.radians(HEADING_DEG),
                look_side=side, crab_rad=math.radians(crab),
            )  # fmt: skip
            runs[crab, side] = simulate(scn, MotionSpec("ideal"), "tactical", seed=5, n_pulses=40)
    return runs


def _emitter(wire: str, path: Path, feed: InsFeed) -> Emitter:
    link = FileLink(path)
    if wire == "mavlink":
        return INS_EMITTERS["mavlink"].to_file(link, feed, InsEmitterOptions(None, 0, 1))
    proto, _, attitude = wire.partition("/")
    if proto == "sbg":
        return SbgEmitter(link, feed, attitude=attitude)
    return SbgCanEmitter(link, feed, "candump", attitude=attitude)


def _decode(wire: str, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(yaw of the attitude, course of the velocity) per INS sample on the wire, rad."""
    if wire == "mavlink":  # pymavlink itself, not the daemon's driver
        conn = mavutil.mavlink_connection(str(path))
        att: dict[int, float] = {}
        vel: dict[int, float] = {}
        want = ["ATTITUDE_QUATERNION", "LOCAL_POSITION_NED"]
        while (m := conn.recv_match(type=want)) is not None:
            if m.get_type() == "ATTITUDE_QUATERNION":
                att[m.time_boot_ms] = float(_yaw_rad(np.array([[m.q1, m.q2, m.q3, m.q4]]))[0])
            else:
                vel[m.time_boot_ms] = math.atan2(m.vy, m.vx)
        common = sorted(set(att) & set(vel))
        return np.array([att[t] for t in common]), np.array([vel[t] for t in common])
    src: Source = SbgFileSource(path) if wire.startswith("sbg/") else CanLogSource(path)
    samples = _drain(src)
    q = {s.t_gps_ns: s.quat for s in samples if isinstance(s, AttitudeSample)}
    v = {s.t_gps_ns: s.vel_ned for s in samples if isinstance(s, VelocitySample)}
    common = sorted(set(q) & set(v))
    course = np.array([math.atan2(v[t][1], v[t][0]) for t in common])
    return _yaw_rad(np.array([q[t] for t in common])), course


WIRES = ("mavlink", "sbg/quat", "sbg/euler", "sbg-can/quat", "sbg-can/euler")


@pytest.mark.parametrize("wire", WIRES)
def test_ins_yaw_leads_the_course_by_the_crab_on_every_wire(
    crabbed_runs: dict[tuple[float, str], SimRun], wire: str, tmp_path: Path
) -> None:
    """Decoded from the bytes, the INS yaw minus the course of the INS velocity is the crab
    (to the tactical grade's heading error and the velocity noise: 0.1 deg)."""
    for (crab, side), run in crabbed_runs.items():
        path = tmp_path / f"{crab:+.0f}-{side}-{INS_EMITTERS[wire.partition('/')[0]].file}"
        em = _emitter(wire, path, InsFeed.from_run(run, Faults()))
        play_fast(em)
        em.close()
        yaw, course = _decode(wire, path)
        assert yaw.size >= 0.9 * run.ins.nav.t_ns.size
        crab_seen = _wrap(yaw - course)
        assert np.degrees(np.median(crab_seen)) == pytest.approx(crab, abs=0.1), (side, wire)
        assert np.degrees(np.abs(crab_seen - math.radians(crab))).max() < 0.5
        course_error = _wrap(course - math.radians(HEADING_DEG))
        assert np.degrees(np.abs(course_error)).max() < 0.1  # the track keeps its heading


@pytest.mark.parametrize("side", SIDES)
@pytest.mark.parametrize("crab_deg", (-8.0, 8.0))
def test_truth_doppler_centroid_is_the_echoes(crab_deg: float, side: str) -> None:
    """The truth's Doppler centroid (the scene centre's, at the beam centre) is what the
    standard correlation estimator measures on the range-compressed echoes of a target there,
    modulo the PRF (8 deg of crab alias it); looking right a positive crab squints the beam
    aft, looking left forward."""
    base = load_preset("ku-vehicle", scale=0.1)
    ground = math.sqrt(base.center_slant_range_m**2 - base.altitude_m**2)
    scn = load_preset(
        "ku-vehicle", scale=0.1, heading_rad=math.radians(HEADING_DEG), look_side=side,
        crab_rad=math.radians(crab_deg), snr_db=None, targets=(Target((0.0, ground, 0.0)),),
    )  # fmt: skip
    toward = -math.copysign(1.0, crab_deg) * (1.0 if side == "right" else -1.0)
    assert scn.beam_squint_rad == pytest.approx(toward * math.radians(abs(crab_deg)))
    prf = scn.radar.prf_hz
    assert abs(scn.doppler_centroid_hz) > prf / 2.0  # aliased
    run = simulate(scn, MotionSpec("ideal"), "ideal")
    rc = compress(scn.radar, np.asarray(run.echo))
    lit = np.flatnonzero(np.abs(rc).max(axis=1) > 0.5 * np.abs(rc).max())
    peaks = rc[lit, np.argmax(np.abs(rc[lit]), axis=1)]
    measured = np.angle(np.sum(peaks[1:] * np.conj(peaks[:-1]))) * prf / (2.0 * np.pi)
    expected = (scn.doppler_centroid_hz + prf / 2.0) % prf - prf / 2.0
    assert measured == pytest.approx(expected, abs=0.5)


def test_a_squint_past_the_horizon_is_refused() -> None:
    with pytest.raises(ConfigError):
        load_preset("ku-vehicle", scale=0.1, crab_rad=math.radians(89.5))


E2E_CRAB_DEG = 8.0


def _ins_azimuth_shift_m(truth: dict[str, Any]) -> float:
    """How far along track the INS's velocity error moves the targets, m: its mean along
    the scene centre's line of sight ``δv`` (the INS's velocities against the true APC's,
    over the pulses) times ``R / v``, a Doppler offset that no autofocus sees (a linear
    phase). The tactical INS's at ±8° of crab: 0.018 m/s, 0.9 m."""
    scn = truth["scenario"]
    t_s = (np.asarray(truth["pulses"]["t_ns"], dtype=np.int64) - truth["pulses"]["t_ns"][0]) / 1e9
    apc = np.asarray(truth["pulses"]["apc_ned"])
    true_vel = np.gradient(apc, t_s, axis=0)
    ins_t_s = (np.asarray(truth["ins"]["t_ns"]) - truth["pulses"]["t_ns"][0]) / 1e9
    ins_vel = np.asarray(truth["ins"]["vel_ned"])
    err = np.stack([np.interp(t_s, ins_t_s, ins_vel[:, j]) for j in range(3)], axis=1) - true_vel
    target = np.asarray(scn["scene_center_ned"]) - apc[apc.shape[0] // 2]
    los = target / np.linalg.norm(target)
    speed = float(np.linalg.norm(true_vel.mean(axis=0)))
    return abs(float(np.mean(err[5:-5] @ los))) * scn["center_slant_range_m"] / speed


@pytest.mark.parametrize("crab_deg", [E2E_CRAB_DEG, -E2E_CRAB_DEG])
def test_crabbed_flight_replayed_focuses(tmp_path: Path, crab_deg: float) -> None:
    """``sarmoco sim --crab-deg ±8`` (scaled ku-vehicle, turbulence, tactical INS) replayed
    from its ``.vrt`` and ``.tlog`` with the configuration the simulator wrote: every target
    focused (PSLR <= -12.5 dB, IRW <= 1.1 x theory in both axes) at its place. The three
    targets sit side by side along track, at the same place in the squinted beam at once:
    the autofocus must take each line's rate at the line's own squint (with the beam
    centre's, -12.39/-12.33/-12.18 dB at +8°, -12.11/-12.45/-12.21 dB at -8°)."""
    sim = [
        "sim", "--preset", "ku-vehicle", "--scale", "0.1", "--motion", "turbulence",
        "--motion-seed", "1", "--heading-deg", str(HEADING_DEG),
        "--crab-deg", str(crab_deg), "--out", str(tmp_path),
    ]  # fmt: skip
    subprocess.run([sys.executable, "-m", "sarmoco", *sim], check=True, capture_output=True)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["scenario"]["crab_rad"] == pytest.approx(math.radians(crab_deg))
    replay = [
        "replay", "--config", str(tmp_path / "sarmoco.toml"),
        "--radar", str(tmp_path / "radar.vrt"), "--nav", str(tmp_path / "nav.tlog"),
        "--out", str(tmp_path / "run.zarr"), "--quiet",
    ]  # fmt: skip
    subprocess.run([sys.executable, "-m", "sarmoco", *replay], check=True, capture_output=True)
    points = store_points(tmp_path / "run.zarr")
    print(  # shown with pytest -s
        f"crab {crab_deg:.0f} deg: "
        + "; ".join(
            f"PSLR az {p['pslr_az_db']:.2f} rg {p['pslr_rg_db']:.2f} dB "
            f"IRW az {p['irw_az_m']:.3f} m"
            for p in points[:3]
        )
    )
    assert_focused(tmp_path, points, 0.5 + _ins_azimuth_shift_m(truth))


def test_sim_and_demo_platform_arguments_take_the_crab() -> None:
    """``--crab-deg`` (``sarmoco sim`` and the demo's platform arguments) reaches the
    scenario in radians; without it the platform flies uncrabbed."""
    scn = load_preset(
        "ku-vehicle", 0.1, **scenario_overrides(platform_arguments(["--crab-deg", "-6.5"]))
    )
    assert scn.crab_rad == pytest.approx(math.radians(-6.5))
    assert (
        load_preset("ku-vehicle", 0.1, **scenario_overrides(platform_arguments([]))).crab_rad == 0
    )
