"""Pulse/INS alignment under stress.

An analytic smooth trajectory (positions, velocities and attitude are exact
derivatives of one process) is sampled by a simulated INS whose link has 2 ms
sampling jitter and 3-5 ms delivery jitter, a 50 ms dropout, packets delivered
out of order, and an INS clock that steps 80 ms ahead until its mapping
re-synchronises. Events are fed in arrival order, as the reader threads would.
Pulses in a gap must be flagged and carry no navigation; every other pulse's
antenna position along the line of sight must be within lambda/16 of the truth
at Ku band (15 GHz), and so must the LOS displacement integrated from the
released velocities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from sarmoco.daemon.aligner import AlignedBlock, Aligner
from sarmoco.daemon.echoring import EchoRing
from sarmoco.daemon.navbuffer import NavBuffer
from sarmoco.processing.geometry import lever_arm_ned
from sarmoco.processing.types import C_MPS, FloatArray
from sarmoco.store.flags import NAV_UNUSABLE, PulseFlag, PushResult

MS = 1_000_000
LAMBDA_KU = C_MPS / 15e9
LEVER = (0.10, 0.35, -0.05)
BETA = np.deg2rad(50.0)
LOS_NED = np.array([0.0, np.sin(BETA), np.cos(BETA)])  # looking right (east) from a north track


def _euler_quat(t: FloatArray) -> FloatArray:
    yaw = 0.05 * np.sin(2 * np.pi * 0.5 * t)
    pitch = 0.03 * np.sin(2 * np.pi * 0.9 * t)
    roll = 0.06 * np.sin(2 * np.pi * 1.7 * t)
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=-1,
    )


def _imu(t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """IMU position (m) and velocity (m/s), NED, of a 30 m/s track with smooth sway."""
    w1, w2, w3 = 2 * np.pi * 0.7, 2 * np.pi * 1.3, 2 * np.pi * 1.1
    pos = np.stack(
        [
            30.0 * t + 0.3 * np.sin(w1 * t),
            0.2 * t + 0.4 * np.sin(w2 * t),
            -100.0 + 0.25 * np.sin(w3 * t + 0.5),
        ],
        axis=-1,
    )
    vel = np.stack(
        [
            30.0 + 0.3 * w1 * np.cos(w1 * t),
            0.2 + 0.4 * w2 * np.cos(w2 * t),
            0.25 * w3 * np.cos(w3 * t + 0.5),
        ],
        axis=-1,
    )
    return pos, vel


def _apc(t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """True antenna phase centre position and velocity."""
    pos, vel = _imu(t)
    d = 1e-6
    arm_rate = lever_arm_ned(_euler_quat(t + d), LEVER) - lever_arm_ned(_euler_quat(t - d), LEVER)
    return pos + lever_arm_ned(_euler_quat(t), LEVER), vel + arm_rate / (2 * d)


@dataclass
class _Run:
    blocks: list[AlignedBlock]
    accepted_t_ns: np.ndarray
    n_stepped: int
    nav: NavBuffer
    aligner: Aligner


def _stressed_run(seed: int) -> _Run:
    rng = np.random.default_rng(seed)
    # INS sample instants: 200 Hz with +-2 ms sampling jitter, correctly stamped.
    t_ins = np.arange(0, 840) * 5 * MS + rng.integers(-2 * MS, 2 * MS, 840)
    t_s = t_ins * 1e-9
    pos, vel = _imu(t_s)
    quat = _euler_quat(t_s)
    dropout = (t_ins >= 1500 * MS) & (t_ins < 1550 * MS)
    stepped = (t_ins >= 2600 * MS) & (t_ins < 3000 * MS)  # until the next time sync
    stamp = t_ins + np.where(stepped, 80 * MS, 0)
    arrival = t_ins + 3 * MS + rng.integers(0, 2 * MS, t_ins.shape[0])
    arrival[::7] += 12 * MS  # reordered: overtaken by the next two samples
    # Pulses at 1 kHz from 0.3 s to 3.8 s, each received 1 ms after transmission.
    t_pulse = 300 * MS + np.arange(3500) * MS
    events = [(int(a), 1, k) for k, a in enumerate(arrival) if not dropout[k]]
    events += [(int(t) + MS, 0, k) for k, t in enumerate(t_pulse)]
    events.sort()

    ring = EchoRing(1024, 8, "int16")
    nav = NavBuffer(history_ns=5_000 * MS, capacity=2048, clock_tolerance_ns=20 * MS)
    aligner = Aligner(
        ring,
        nav,
        max_gap_ns=20 * MS,
        latency_budget_ns=200 * MS,
        lever_arm_body_m=LEVER,
        max_block=128,
    )
    blocks: list[AlignedBlock] = []
    accepted: list[int] = []
    for now, kind, k in events:
        if kind == 0:
            slot = ring.reserve()
            assert slot is not None
            slot.samples[...] = k % 100
            ring.commit(slot, t_ns=int(t_pulse[k]), pulse_id=k)
        else:
            r1 = nav.push_velocity(int(stamp[k]), vel[k], pos[k], rx_ns=now)
            r2 = nav.push_attitude(int(stamp[k]), quat[k], rx_ns=now)
            assert r1 == r2
            if r1 is PushResult.ACCEPTED:
                accepted.append(int(t_ins[k]))
        while (block := aligner.poll(now)) is not None:
            blocks.append(block)
    if (block := aligner.flush()) is not None:
        blocks.append(block)
    return _Run(blocks, np.sort(np.array(accepted)), int(stepped.sum()), nav, aligner)


@pytest.mark.parametrize("seed", [1, 2])
def test_alignment_under_stress(seed: int) -> None:
    run = _stressed_run(seed)
    t = np.concatenate([b.echoes.t_ns for b in run.blocks])
    ids = np.concatenate([b.echoes.pulse_id for b in run.blocks])
    flags = np.concatenate([b.echoes.flags for b in run.blocks])
    pos = np.concatenate([b.nav.pos_ned for b in run.blocks])
    vel = np.concatenate([b.nav.vel_ned for b in run.blocks])
    valid = np.concatenate([b.nav.valid for b in run.blocks])
    np.testing.assert_array_equal(ids, np.arange(3500))  # all released, in order

    # Flagged exactly where the samples that were kept leave a gap wider than max_gap.
    acc = run.accepted_t_ns
    i = np.searchsorted(acc, t, side="right") - 1
    expect_gap = acc[i + 1] - acc[i] > 20 * MS
    gap = (flags & NAV_UNUSABLE) != 0
    np.testing.assert_array_equal(gap, expect_gap)
    # The dropout is shorter than the latency budget: a gap once the INS resumed.
    # Through the clock step nothing usable arrives for 400 ms: timeouts, then gaps.
    in_dropout = (t >= 1500 * MS) & (t < 1550 * MS)
    in_step = (t >= 2600 * MS) & (t < 3000 * MS)
    assert gap[in_dropout | in_step].all()
    assert (flags[in_dropout] == PulseFlag.NAV_GAP).all()
    assert (flags[in_step] == PulseFlag.NAV_TIMEOUT).any()
    assert gap.sum() < in_dropout.sum() + in_step.sum() + 30  # only the gaps' edges beyond
    np.testing.assert_array_equal(valid, ~gap)
    assert np.isnan(pos[gap]).all() and np.isnan(vel[gap]).all()
    counts = run.nav.counts()
    assert counts["kinematics_clock_rejected"] == run.n_stepped
    assert counts["kinematics_reordered"] > 50
    assert (
        run.aligner.nav_gap + run.aligner.nav_timeout == gap.sum() and run.aligner.released == 3500
    )

    # The others: antenna position along the LOS within lambda/16 of the truth ...
    true_pos, true_vel = _apc(t * 1e-9)
    los_err = (pos[valid] - true_pos[valid]) @ LOS_NED
    print(
        f"seed {seed}: max |LOS error| {np.abs(los_err).max() * 1e3:.4f} mm "
        f"(lambda/16 = {LAMBDA_KU / 16 * 1e3:.3f} mm), flagged {gap.sum()} pulses"
    )
    assert np.abs(los_err).max() < LAMBDA_KU / 16
    vel_err = np.abs((vel[valid] - true_vel[valid]) @ LOS_NED).max()
    print(f"max |LOS velocity error| {vel_err * 1e3:.3f} mm/s")
    assert vel_err < 5e-3  # the lever arm's rate is one-sided next to a gap
    # ... and the LOS displacement integrated from the released velocities too
    # (what the D_los compensation does), over each run of unflagged pulses.
    edges = np.flatnonzero(np.diff(valid.astype(np.int8)) != 0) + 1
    for seg in np.split(np.arange(t.shape[0]), edges):
        if not valid[seg[0]] or seg.shape[0] < 2:
            continue
        v_los = vel[seg] @ LOS_NED
        dt = np.diff(t[seg]) * 1e-9
        d_los = np.concatenate([[0.0], np.cumsum(0.5 * (v_los[1:] + v_los[:-1]) * dt)])
        truth = (true_pos[seg] - true_pos[seg[0]]) @ LOS_NED
        assert np.abs(d_los - truth).max() < LAMBDA_KU / 16


def test_pulse_velocity_is_the_ins_velocity_not_its_positions_derivative() -> None:
    """An aided INS's positions as a MAVLink autopilot sends them: stamped to its 1 ms
    clock (``time_boot_ms``; up to 15 mm along track at 30 m/s) and moved by a 3 cm
    position update at 1.0 s; its velocity is exact. The pulses' velocity must follow the
    velocity: the derivative of the position cubic made metres per second of it."""
    t_ins = np.arange(0, 430) * 4_700_000 + 333_333  # 213 Hz, off the millisecond grid
    pos, vel = _imu(t_ins * 1e-9)
    pos = pos + np.where(t_ins >= 1000 * MS, 0.03, 0.0)[:, None] * np.array([0.6, 0.8, 0.0])
    stamp = (t_ins + MS // 2) // MS * MS  # to the nearest millisecond
    ring = EchoRing(2048, 4)
    nav = NavBuffer(history_ns=5_000 * MS, capacity=1024)
    aligner = Aligner(ring, nav, max_gap_ns=20 * MS, latency_budget_ns=200 * MS, max_block=4096)
    for k in range(t_ins.shape[0]):
        nav.push_velocity(int(stamp[k]), vel[k], pos[k])
        nav.push_attitude(int(stamp[k]), (1.0, 0.0, 0.0, 0.0))
    t_pulse = 100 * MS + np.arange(1800) * MS
    for k, t in enumerate(t_pulse):
        slot = ring.reserve()
        assert slot is not None
        ring.commit(slot, t_ns=int(t), pulse_id=k)
    blocks = []
    while (block := aligner.poll(now_ns=3_000 * MS)) is not None:
        blocks.append(block)
    t = np.concatenate([b.echoes.t_ns for b in blocks])
    got = np.concatenate([b.nav.vel_ned for b in blocks])
    assert t.shape[0] == 1800 and np.isfinite(got).all()
    _, true_vel = _imu(t * 1e-9)
    err = np.abs(got - true_vel)
    print(f"pulse velocity error: max {err.max() * 1e3:.2f} mm/s, LOS "
          f"{np.abs((got - true_vel) @ LOS_NED).max() * 1e3:.2f} mm/s")  # fmt: skip
    # linear between 213 Hz samples of a 1.3 Hz sway (4 mm/s), and the stamps' +-0.5 ms
    # at its 27 m/s^2 (14 mm/s); the positions' derivative gave 14.5 m/s
    assert err.max() < 0.02
    # D_los over the 1.8 s: the INS's relative motion, not its position update
    v_los = got @ LOS_NED
    d_los = np.cumsum(0.5 * (v_los[1:] + v_los[:-1]) * np.diff(t) * 1e-9)
    true_pos, _ = _imu(t * 1e-9)
    assert np.abs(d_los - (true_pos[1:] - true_pos[0]) @ LOS_NED).max() < LAMBDA_KU / 16


def test_timeout_flag_velocity_only_source_and_flush() -> None:
    ring = EchoRing(16, 4)
    nav = NavBuffer(history_ns=5_000 * MS)
    aligner = Aligner(ring, nav, max_gap_ns=20 * MS, latency_budget_ns=100 * MS, max_block=256)
    for k, t in enumerate((0, 10, 20)):
        nav.push_velocity(t * MS, (30.0, 1.0 + k, 0.0))  # no position from this source
        nav.push_attitude(t * MS, (1.0, 0.0, 0.0, 0.0))
    for k, t in enumerate((5, 15, 25)):
        slot = ring.reserve()
        assert slot is not None
        ring.commit(slot, t_ns=t * MS, pulse_id=k)
    block = aligner.poll(now_ns=26 * MS)
    assert block is not None and len(block) == 2  # the third waits for the INS
    np.testing.assert_allclose(block.nav.vel_ned[:, 1], [1.5, 2.5])
    assert np.isnan(block.nav.pos_ned).all() and block.nav.valid.all()
    assert aligner.poll(now_ns=120 * MS) is None
    late = aligner.poll(now_ns=126 * MS)
    assert late is not None and late.echoes.flags[0] == PulseFlag.NAV_TIMEOUT
    assert not late.nav.valid[0] and aligner.nav_timeout == 1
    assert aligner.flush() is None


def test_short_silence_bridged_long_ones_flagged() -> None:
    """A 200 Hz INS silent for 0.3 s, 1 s and 10 s; pulses at 100 Hz, events fed in time
    order with 5 ms INS latency. The 0.3 s silence (<= bridge_gap 0.4 s) is bridged: its
    pulses wait for the samples after it, leave flagged NAV_BRIDGED only, with navigation;
    every pulse of the 1 s and 10 s silences is flagged NAV_UNUSABLE with NaN navigation."""
    silences = ((1000, 1300), (3000, 4000), (5000, 15000))
    t_ins = np.arange(0, 17000, 5) * MS
    t_ins = t_ins[~np.any([(t_ins >= a * MS) & (t_ins < b * MS) for a, b in silences], axis=0)]
    t_pulse = np.arange(5, 16500, 10) * MS
    pos, vel = _imu(t_ins * 1e-9)
    quat = _euler_quat(t_ins * 1e-9)
    ring = EchoRing(4096, 4)
    aligner = Aligner(ring, NavBuffer(), 50 * MS, 500 * MS, 256, bridge_gap_ns=400 * MS)
    events = sorted([(int(t), 0, k) for k, t in enumerate(t_pulse)]
                    + [(int(t) + 5 * MS, 1, k) for k, t in enumerate(t_ins)])  # fmt: skip
    blocks: list[AlignedBlock] = []
    for now, kind, k in events:
        if kind == 0:
            slot = ring.reserve()
            assert slot is not None
            ring.commit(slot, t_ns=int(t_pulse[k]), pulse_id=k)
        else:
            aligner.nav.push_velocity(int(t_ins[k]), vel[k], pos[k])
            aligner.nav.push_attitude(int(t_ins[k]), quat[k])
        while (block := aligner.poll(now)) is not None:
            blocks.append(block)
    if (block := aligner.flush()) is not None:
        blocks.append(block)
    t = np.concatenate([b.echoes.t_ns for b in blocks])
    flags = np.concatenate([b.echoes.flags for b in blocks])
    got_pos = np.concatenate([b.nav.pos_ned for b in blocks])
    np.testing.assert_array_equal(t, t_pulse)
    in_s = [(t >= a * MS) & (t < b * MS) for a, b in silences]
    bridged = (flags & PulseFlag.NAV_BRIDGED) != 0
    unusable = (flags & NAV_UNUSABLE) != 0
    print(f"0.3 s silence: {bridged[in_s[0]].sum()} of {in_s[0].sum()} bridged; 1 s: "
          f"{unusable[in_s[1]].sum()} of {in_s[1].sum()} flagged; 10 s: "
          f"{unusable[in_s[2]].sum()} of {in_s[2].sum()} flagged")  # fmt: skip
    assert (flags[in_s[0]] == PulseFlag.NAV_BRIDGED).all()
    los_err = np.abs((got_pos[in_s[0]] - _imu(t[in_s[0]] * 1e-9)[0]) @ LOS_NED).max()
    print(f"bridged |LOS error| {los_err * 1e3:.2f} mm")
    assert los_err < LAMBDA_KU / 4
    assert unusable[in_s[1] | in_s[2]].all() and not bridged[in_s[1] | in_s[2]].any()
    assert np.isnan(got_pos[in_s[1] | in_s[2]]).all()
    assert not (bridged | unusable)[~np.any(in_s, axis=0)].any()
    assert aligner.nav_bridged == in_s[0].sum()
