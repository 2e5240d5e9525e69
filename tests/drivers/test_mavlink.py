"""MAVLink: live UDP round trip (TIMESYNC, rate requests, signing), real ArduPilot logs
(.tlog, dataflash .bin) against pymavlink, and damaged input."""

from __future__ import annotations

import logging
import math
import socket
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sarmoco.drivers.attitude import euler_to_quat
from sarmoco.drivers.clock import unix_ns_to_gps_ns
from sarmoco.drivers.dataflash import DataflashSource
from sarmoco.drivers.mavlink import FINER_HOLD_MS, MavlinkSource, mavlink2, mavutil
from sarmoco.drivers.samples import AttitudeSample, VelocitySample
from tests.conftest import SHARED_DATA
from tests.drivers.mapbounds import observe_map_bounds

DATA = SHARED_DATA / "mavlink"
TLOG = DATA / "arduplane_quadplane_sitl.tlog"
DFBIN = DATA / "arduplane_sitl_dataflash.bin"
KEY = bytes(range(32))
SKEW = 50e-6


class Autopilot(threading.Thread):
    """A simulated autopilot: its own boot clock (50 ppm fast), answers TIMESYNC; with
    ``system_time``, SYSTEM_TIME (its GPS-derived UNIX time) every 0.25 s. Its clock is the
    machine's wall clock as it was when it started, run on the monotonic clock."""

    def __init__(
        self,
        port: int,
        key: bytes | None = None,
        duration_s: float = 2.5,
        system_time: bool = False,
        wall: Callable[[], int] = time.time_ns,  # the machine's, bound at import
    ) -> None:
        super().__init__()
        self.system_time = system_time
        before = wall()
        mono = time.monotonic_ns()
        after = wall()
        self._wall0 = (before + after) // 2 - mono
        self.truth_error_ns = (after - before + 1) // 2
        """How far the truth's UTC may be off: its wall and monotonic reads paired, ns."""
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=1, source_component=1
        )
        if key is not None:
            self.conn.setup_signing(key, sign_outgoing=True)
        self.h0 = self.unix_ns() - 300 * 10**9
        self.duration_s = duration_s
        self.truth: dict[int, tuple[int, tuple[float, ...], tuple[float, ...]]] = {}
        self.commands: list[tuple[int, float]] = []
        self.timesync_requests: list[float] = []
        """Monotonic times at which TIMESYNC requests were answered, s."""

    def unix_ns(self) -> int:
        """UNIX time as the autopilot's GPS gives it, ns."""
        return self._wall0 + time.monotonic_ns()

    def boot_ns(self) -> int:
        return round((self.unix_ns() - self.h0) * (1 + SKEW))

    def run(self) -> None:
        mav = self.conn.mav
        end = time.monotonic() + self.duration_s
        k = 0
        while time.monotonic() < end:
            ms = self.boot_ns() // 10**6
            if k % 25 == 0:
                mav.heartbeat_send(1, 3, 0, 0, 0)
                if self.system_time:
                    mav.system_time_send((self.h0 + round(ms * 10**6 / (1 + SKEW))) // 1000, ms)
            vel = (20.0 + 0.01 * k, 1.5, -0.2 * math.sin(k / 9))
            q = euler_to_quat(0.05 * math.sin(k / 11), 0.02, 1.0 + 0.001 * k)
            mav.local_position_ned_send(ms, 0.2 * k, 0.0, -50.0, *vel)
            mav.attitude_quaternion_send(ms, *q, 0, 0, 0)
            truth_unix = self.h0 + round(ms * 10**6 / (1 + SKEW))
            self.truth[ms] = (unix_ns_to_gps_ns(truth_unix, 18), vel, q)
            while (m := self.conn.recv_match(blocking=False)) is not None:
                if m.get_type() == "TIMESYNC" and m.tc1 == 0:
                    mav.timesync_send(self.boot_ns(), m.ts1)
                    self.timesync_requests.append(time.monotonic())
                elif m.get_type() == "COMMAND_LONG":
                    self.commands.append((m.command, m.param1))
            k += 1
            time.sleep(0.01)


def run_link(
    key: bytes | None,
    sender_key: bytes | None,
    timesync_period_s: float = 0.1,
    source: MavlinkSource | None = None,
) -> tuple[MavlinkSource, Autopilot, list]:
    src = source or MavlinkSource(
        "udpin:127.0.0.1:0", signing_key=key, timesync_period_s=timesync_period_s
    )
    port = src._conn.port.getsockname()[1]
    ap = Autopilot(port, sender_key)
    ap.start()
    got: list[tuple[object, int]] = []
    while ap.is_alive():
        batch = src.poll(0.02)
        got += [(s, src.time_bound_ns) for s in batch]
    ap.join()
    return src, ap, got


def test_udp_round_trip_timesync_rates() -> None:
    """Every sample's GPS time is within the bound the estimator stated when it mapped
    that sample. (Judged against the bound read after a whole poll, one sample failed in
    1 of 7 CI runs: a TIMESYNC reply later in the same poll had narrowed the bound.)"""
    src = MavlinkSource("udpin:127.0.0.1:0", timesync_period_s=0.1)
    bound_at_map = observe_map_bounds(src)
    src, ap, got = run_link(None, None, source=src)
    src.close()
    assert (mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 32.0) in ap.commands  # LOCAL_POSITION_NED
    assert (mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 31.0) in ap.commands  # ATTITUDE_QUATERNION
    vel = [s for s, _ in got if isinstance(s, VelocitySample)]
    att = [s for s, _ in got if isinstance(s, AttitudeSample)]
    assert len(vel) > 100 and len(att) > 100
    errors = []
    for s in vel[len(vel) // 2 :] + att[len(att) // 2 :]:
        t, v, q = ap.truth[s.device_time_ns // 10**6]
        errors.append(abs(s.t_gps_ns - t))
        assert abs(s.t_gps_ns - t) <= bound_at_map[s.device_time_ns] + ap.truth_error_ns, (
            s.t_gps_ns - t,
            bound_at_map[s.device_time_ns],
        )
        if isinstance(s, VelocitySample):
            assert s.vel_ned == pytest.approx(v, abs=1e-5)
        else:
            assert s.quat == pytest.approx(q, abs=1e-6)
    assert max(errors) < 20e6 and src.time_bound_ns < 20e6  # loopback: well under 20 ms


class OtherSystem(threading.Thread):
    """System 42 on the autopilot's link, from its own socket: random bytes, frames with a
    broken CRC, a companion computer's HEARTBEAT, and well-formed LOCAL_POSITION_NED and
    ATTITUDE_QUATERNION with values of its own (99 m/s north); it answers TIMESYNC
    requests with a boot clock 5 s off. It starts before the autopilot and goes on while
    the autopilot speaks."""

    SYSID = 42

    def __init__(self, port: int, duration_s: float) -> None:
        super().__init__()
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=self.SYSID, source_component=191
        )
        self.duration_s = duration_s
        self.sent = 0

    def run(self) -> None:
        mav, rng = self.conn.mav, np.random.default_rng(42)
        end = time.monotonic() + self.duration_s
        k = 0
        while time.monotonic() < end:
            ms = k * 10
            if k % 10 == 0:
                mav.heartbeat_send(
                    mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 4
                )
            self.conn.write(rng.bytes(int(rng.integers(1, 200))))
            frame = bytearray(mavlink2.MAVLink_local_position_ned_message(
                ms, 0, 0, 0, 99.0, 0, 0).pack(mav))  # fmt: skip
            frame[12] ^= 0x10  # a payload bit: the CRC no longer matches
            self.conn.write(bytes(frame))
            mav.local_position_ned_send(ms, 1.0 * k, 0.0, -50.0, 99.0, 0.0, 0.0)
            mav.attitude_quaternion_send(ms, 0.0, 1.0, 0.0, 0.0, 0, 0, 0)
            self.sent += 3
            while (m := self.conn.recv_match(blocking=False)) is not None:
                if m.get_type() == "TIMESYNC" and m.tc1 == 0:
                    mav.timesync_send(time.time_ns() + 5 * 10**9, m.ts1)
            k += 1
            time.sleep(0.01)


def test_the_autopilot_is_chosen_not_the_first_system_heard(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """System 42 talks first and throughout; the HEARTBEAT of system 1 says it is an
    autopilot: its navigation is decoded, its time mapped within the stated bounds, the
    rate requests go to it, and system 42 is named in the log and its messages counted."""
    src = MavlinkSource("udpin:127.0.0.1:0", timesync_period_s=0.1)
    bound_at_map = observe_map_bounds(src)
    port = src._conn.port.getsockname()[1]
    other = OtherSystem(port, duration_s=3.2)
    got: list[Any] = []
    with caplog.at_level(logging.INFO, logger="sarmoco.drivers.mavlink"):
        other.start()
        t_end = time.monotonic() + 0.5  # system 42 alone on the link
        while time.monotonic() < t_end:
            got += src.poll(0.02)
        assert got == [] and src.system_id == 0
        ap = Autopilot(port)
        ap.start()
        while ap.is_alive():
            got += src.poll(0.02)
        ap.join()
        other.join()
        src.close()
    vel = [s for s in got if isinstance(s, VelocitySample)]
    att = [s for s in got if isinstance(s, AttitudeSample)]
    assert len(vel) > 100 and len(att) > 100
    assert src.system_id == 1
    assert (mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 32.0) in ap.commands
    for s in vel[len(vel) // 2 :] + att[len(att) // 2 :]:
        t, v, q = ap.truth[s.device_time_ns // 10**6]
        assert abs(s.t_gps_ns - t) <= bound_at_map[s.device_time_ns] + ap.truth_error_ns
        if isinstance(s, VelocitySample):
            assert s.vel_ned == pytest.approx(v, abs=1e-5)
        else:
            assert s.quat == pytest.approx(q, abs=1e-6)
    assert src.time_bound_ns < 20e6
    assert other.sent / 3 < src.other_systems[42] <= other.sent  # good frames, some eaten
    assert src.counters.rejected >= src.other_systems[42]
    assert src.counters.parse_errors + src.counters.crc_errors > 0
    assert "listening to the autopilot of system 1 (component 1" in caplog.text
    assert "system 42 also speaks on the link" in caplog.text
    assert f"system 42: {src.other_systems[42]}" in caplog.text


@pytest.mark.parametrize(
    ("wrong_s", "step_s", "verdict"),
    [(0, 10, "ignored"), (0, -10, "ignored"), (0, 3600, "ignored"), (0, -3600, "ignored"),
     (-3600, 3600, "taken")],
)  # fmt: skip
def test_a_wall_clock_step_moves_no_sample(
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    wrong_s: int,
    step_s: int,
    verdict: str,
) -> None:
    """The host's wall clock, ``wrong_s`` off GPS time at first, steps by ``step_s`` 1.2 s
    into the link and stays there; the autopilot's clock and GPS time do not. A step away
    from the autopilot's SYSTEM_TIME is ignored (TIMESYNC goes on, on the monotonic clock),
    one towards it (chrony correcting a wrong clock) is taken; either way every sample from
    0.5 s after it (the first half second: TIMESYNC's settling, as in the round trip above)
    keeps its GPS time within the stated bound, and the log says what happened."""
    wall = time.time_ns
    offset = {"ns": wrong_s * 10**9}
    monkeypatch.setattr(time, "time_ns", lambda: wall() + offset["ns"])
    src = MavlinkSource("udpin:127.0.0.1:0", timesync_period_s=0.05)
    bound_at_map = observe_map_bounds(src)
    ap = Autopilot(src._conn.port.getsockname()[1], duration_s=3.5, system_time=True)
    ap.start()
    t_step = time.monotonic() + 1.2
    got: list[Any] = []
    with caplog.at_level(logging.WARNING, logger="sarmoco.drivers.mavlink"):
        while ap.is_alive():
            if offset["ns"] == wrong_s * 10**9 and time.monotonic() >= t_step:
                offset["ns"] += step_s * 10**9
            got += [(s, time.monotonic()) for s in src.poll(0.02)]
    ap.join()
    src.close()
    late = [t for t in ap.timesync_requests if t > t_step + 0.5]
    assert len(late) > 10  # TIMESYNC goes on after the step
    after = [s for s, t in got if isinstance(s, VelocitySample | AttitudeSample) and
             t > t_step + 0.5]  # fmt: skip
    assert len(after) > 200
    for s in after:
        t = ap.truth[s.device_time_ns // 10**6][0]
        assert abs(s.t_gps_ns - t) <= bound_at_map[s.device_time_ns] + ap.truth_error_ns, (
            s.t_gps_ns - t
        )
    assert src.time_bound_ns < 20e6
    steps = [r.getMessage() for r in caplog.records if "wall clock stepped" in r.getMessage()]
    assert len(steps) == 1 and f"stepped by {step_s:+.3f} s" in steps[0]
    assert f"the step is {verdict}" in steps[0]


@pytest.mark.parametrize("n_messages", [300, 2500])
def test_a_log_without_an_autopilot_heartbeat_uses_the_first_system(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, n_messages: int
) -> None:
    """A telemetry log with no HEARTBEAT at all (system 5, then system 9 too): every
    sample of system 5 is decoded, whether the log ends before a system's hold is full
    or after; system 9 is counted."""
    out = bytearray()
    mav5 = mavlink2.MAVLink(None, srcSystem=5, srcComponent=1)
    mav9 = mavlink2.MAVLink(None, srcSystem=9, srcComponent=1)
    unix0 = 1_700_000_000_000_000  # µs
    for k in range(n_messages):
        ms = 1000 + 10 * k
        records = [(mav5, mavlink2.MAVLink_local_position_ned_message(ms, 0, 0, 0, 1.0, 0, 0))]
        if k % 50 == 0:
            records.append((mav5, mavlink2.MAVLink_system_time_message(unix0 + ms * 1000, ms)))
        if k > 10:
            records.append(
                (mav9, mavlink2.MAVLink_local_position_ned_message(ms, 0, 0, 0, 9.0, 0, 0))
            )
        for mav, msg in records:
            out += struct.pack(">Q", unix0 + ms * 1000) + msg.pack(mav)
    path = tmp_path / "nohb.tlog"
    path.write_bytes(bytes(out))
    with (
        caplog.at_level(logging.WARNING, logger="sarmoco.drivers.mavlink"),
        MavlinkSource(str(path)) as src,
    ):
        vel = [s for s in src.samples() if isinstance(s, VelocitySample)]
    assert len(vel) == n_messages and {s.vel_ned[0] for s in vel} == {1.0}
    assert src.system_id == 5 and src.other_systems[9] == n_messages - 11
    assert "no HEARTBEAT of an autopilot in the log: using system 5" in caplog.text


def test_timesync_settles_quickly_then_slows_down() -> None:
    """Requests go five times faster until the estimator has its three exchanges (the
    samples wait for them), then at the configured period."""
    src, ap, got = run_link(None, None, timesync_period_s=0.25)
    src.close()
    t = np.array(ap.timesync_requests)
    assert t.size >= 8
    assert t[2] - t[0] < 0.15  # three exchanges in ~0.1 s, not 0.5 s
    assert np.median(np.diff(t[4:])) == pytest.approx(0.25, abs=0.03)
    assert src.decoder.model.timesync.ready and got


def test_signing_rejects_unsigned_and_bad_keys() -> None:
    src, _, got = run_link(KEY, KEY)
    assert sum(isinstance(s, VelocitySample) for s, _ in got) > 100
    assert src.counters.rejected == 0
    n_before = len(got)
    for key in (None, bytes(32)):  # unsigned, then signed with the wrong key
        rogue = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{src._conn.port.getsockname()[1]}", source_system=1
        )
        if key is not None:
            rogue.setup_signing(key, sign_outgoing=True)
        for ms in range(10):
            rogue.mav.local_position_ned_send(ms, 0, 0, 0, 99.0, 99.0, 99.0)
        rogue.close()
    time.sleep(0.1)
    late = src.poll(0.2)
    src.close()
    assert not any(isinstance(s, VelocitySample) and s.vel_ned[0] == 99.0 for s in late)
    assert src.counters.rejected >= 20 and n_before > 0


def test_tlog_matches_pymavlink() -> None:
    ref: dict[str, dict[int, object]] = {"LOCAL_POSITION_NED": {}, "ATTITUDE": {}}
    offsets = []
    log = mavutil.mavlink_connection(str(TLOG))
    while (m := log.recv_match(type=[*ref, "SYSTEM_TIME"])) is not None:
        if m.get_type() == "SYSTEM_TIME":
            offsets.append((m.time_boot_ms, m.time_unix_usec * 1000 - m.time_boot_ms * 10**6))
        else:
            ref[m.get_type()].setdefault(m.time_boot_ms, m)
    off_t, off = np.array(offsets).T
    with MavlinkSource(str(TLOG)) as src:
        samples = list(src.samples())
    for name, kind in (("LOCAL_POSITION_NED", VelocitySample), ("ATTITUDE", AttitudeSample)):
        ours: list[Any] = [
            s for s in samples if isinstance(s, kind) and s.source == f"mavlink.{name}"
        ]
        assert len(ours) >= 0.95 * len(ref[name])
        t = np.array([s.t_gps_ns for s in ours])
        assert np.all(np.diff(t) > 0)
        for s in ours:
            ms = s.device_time_ns // 10**6
            m = ref[name][ms]
            if kind is VelocitySample:
                assert s.vel_ned == (m.vx, m.vy, m.vz)  # type: ignore[attr-defined]
            else:
                want = euler_to_quat(m.roll, m.pitch, m.yaw)  # type: ignore[attr-defined]
                assert s.quat == pytest.approx(want, abs=1e-9)
            unix = ms * 10**6 + np.interp(ms, off_t, off)
            assert abs(s.t_gps_ns - unix_ns_to_gps_ns(int(unix), 18)) < 2e6


def _tlog_sequence_loss(data: bytes) -> tuple[int, int]:
    """(gaps, lost messages) from the sequence numbers of a .tlog, per sender."""
    last: dict[tuple[int, int], int] = {}
    gaps = lost = ofs = 0
    while ofs + 8 + 6 <= len(data):
        frame = data[ofs + 8 :]
        v2 = frame[0] == 0xFD
        seq, sysid, compid = frame[4:7] if v2 else frame[2:5]
        size = (12 + (13 if frame[2] & 1 else 0) if v2 else 8) + frame[1]
        if (sysid, compid) in last and (n := (seq - last[(sysid, compid)] - 1) % 256):
            gaps, lost = gaps + 1, lost + n
        last[(sysid, compid)] = seq
        ofs += 8 + size
    assert ofs == len(data)
    return gaps, lost


def test_tlog_counters_are_truthful() -> None:
    """Counters of a whole ArduPilot log agree with the file, from its first message on."""
    data = TLOG.read_bytes()
    gaps, lost = _tlog_sequence_loss(data)
    pym = mavutil.mavlink_connection(str(TLOG))
    n = stale = 0
    last: dict[str, int] = {}
    finer = -(10**9)  # boot time of the latest LOCAL_POSITION_NED, ms
    while (m := pym.recv_match()) is not None:  # pymavlink's own tally on a fresh reader
        n += 1
        name = m.get_type()
        if name in ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ATTITUDE", "SYSTEM_TIME"):
            if name == "SYSTEM_TIME" and not m.time_unix_usec:
                continue
            finer = m.time_boot_ms if name == "LOCAL_POSITION_NED" else finer
            if name == "GLOBAL_POSITION_INT" and 0 <= m.time_boot_ms - finer <= FINER_HOLD_MS:
                continue  # the finer message of the quantity arrives: this one gives no sample
            stale += m.time_boot_ms <= last.get(name, -1)  # same boot time: discarded
            last[name] = max(m.time_boot_ms, last.get(name, -1))
    with MavlinkSource(str(TLOG)) as src:
        for _ in src.samples():
            pass
    c = src.counters
    assert (c.frames, c.crc_errors, c.parse_errors) == (n, 0, 0)
    assert c.bytes == len(data) - 8 * n  # every frame byte, not the tlog timestamps
    assert c.gaps == gaps and c.drops == lost + stale  # was + 1125 from pymavlink's index pass
    assert gaps > 0 and lost > 0  # (this SITL log does have real sequence gaps)


def test_tlog_sequence_skip_counted_once(tmp_path: Path) -> None:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    path = tmp_path / "skip.tlog"
    with path.open("wb") as f:
        for i in range(40):
            mav.seq = (i + (7 if i >= 20 else 0)) % 256  # seven messages lost on the link
            frame = mav.local_position_ned_encode(1000 + 20 * i, 0, 0, 0, 1.0, 0, 0).pack(mav)
            f.write((1_700_000_000_000_000 + 20_000 * i).to_bytes(8, "big") + frame)
    with MavlinkSource(str(path)) as src:
        for _ in src.samples():
            pass
    c = src.counters
    assert (c.frames, c.gaps, c.drops) == (40, 1, 7)


def test_dataflash_matches_pymavlink() -> None:
    log = mavutil.mavlink_connection(str(DFBIN))
    ref: dict[tuple[str, int], object] = {}
    gps = []
    while (m := log.recv_match(type=["NKF1", "NKQ1", "GPS"])) is not None:
        if m.get_type() == "GPS":
            gps.append((m.TimeUS, (m.GWk * 604_800_000 + m.GMS) * 10**6))
        else:
            ref[(m.get_type(), m.TimeUS)] = m
    with DataflashSource(DFBIN) as src:
        samples = list(src.samples())
    vel: list[Any] = [s for s in samples if isinstance(s, VelocitySample)]
    att: list[Any] = [s for s in samples if isinstance(s, AttitudeSample)]
    assert len(vel) == sum(k == "NKF1" for k, _ in ref) and len(att) == len(vel)
    for s in vel:
        m = ref[("NKF1", s.device_time_ns // 1000)]
        assert s.vel_ned == (m.VN, m.VE, m.VD)  # type: ignore[attr-defined]
    for s in att:
        m = ref[("NKQ1", s.device_time_ns // 1000)]
        want = np.array([m.Q1, m.Q2, m.Q3, m.Q4])  # type: ignore[attr-defined]
        np.testing.assert_allclose(s.quat, want / np.linalg.norm(want), atol=1e-9)
    for kind in (vel, att):
        t = np.array([s.t_gps_ns for s in kind])
        assert np.all(np.diff(t) > 0)
    g_t, g_ns = np.array(gps, dtype=np.int64).T
    offset = np.median(g_ns - g_t * 1000)  # GPS time of the log clock, 5 Hz records
    for s in vel + att:
        assert abs(s.t_gps_ns - (s.device_time_ns + offset)) < 3e8


# --- robustness ------------------------------------------------------------------------

_MAV = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
_GOOD = [
    _MAV.local_position_ned_encode(1000 + 20 * i, 0, 0, 0, float(i), 0, 0).pack(_MAV)
    for i in range(6)
]
_SRC: list[MavlinkSource] = []


def _source() -> tuple[MavlinkSource, socket.socket]:
    if not _SRC:
        _SRC.append(MavlinkSource("udpin:127.0.0.1:0", host_clock_is_utc=False))
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect(_SRC[0]._conn.port.getsockname())
    return _SRC[0], tx


@settings(max_examples=200, deadline=None)
@given(
    garbage=st.binary(max_size=300),
    idx=st.integers(0, 5),
    flips=st.lists(st.tuples(st.integers(0, 40), st.integers(0, 7)), max_size=3),
    cut=st.integers(0, 60),
)
def test_damaged_udp_input_never_raises(
    garbage: bytes, idx: int, flips: list[tuple[int, int]], cut: int
) -> None:
    src, tx = _source()
    bad = bytearray(_GOOD[idx])
    for byte, bit in flips:
        if byte < len(bad):
            bad[byte] ^= 1 << bit
    frames0 = src.counters.frames
    tx.send(garbage + bytes(bad[:cut]))
    # pymavlink consumes the whole length a damaged header announces (up to 280 bytes)
    # before it resynchronises; packets inside that span are lost, the ones after survive
    tx.send(bytes(300))
    tx.send(b"".join(_GOOD))
    tx.close()
    deadline = time.monotonic() + 2
    while src.counters.frames - frames0 < 5 and time.monotonic() < deadline:
        src.poll(0.01)
    assert src.counters.frames - frames0 >= 5  # the packets after the damage came through


@pytest.mark.parametrize("byte, bit", [(7, 6), (9, 0)])  # msgid 32 -> 96 or 65568: not in dialect
def test_damaged_message_id_is_a_parse_error(byte: int, bit: int) -> None:
    src, tx = _source()
    bad = bytearray(_GOOD[0])
    bad[byte] ^= 1 << bit
    before = src.counters.snapshot()
    tx.send(bytes(bad) + _GOOD[1])
    tx.close()
    deadline = time.monotonic() + 2
    while src.counters.frames == before["frames"] and time.monotonic() < deadline:
        src.poll(0.01)
    after = src.counters.snapshot()
    assert after["parse_errors"] - before["parse_errors"] == 1  # pymavlink's UNKNOWN_<id>
    assert after["frames"] - before["frames"] == 1  # only the intact second frame
