"""The simulated autopilot: MAVLink 2 round trips through UDP, TCP, a pty and a .tlog."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.demo import free_udp_port
from sarmoco.drivers.mavlink import REQUESTED_RATES_HZ as DAEMON_RATES
from sarmoco.drivers.mavlink import MavlinkSource
from sarmoco.drivers.samples import AttitudeSample, Sample, VelocitySample
from sarmoco.errors import ConfigError
from sarmoco.sim.emit_mavlink import MavlinkEmitter
from sarmoco.sim.faults import Faults, PacketFaults
from sarmoco.sim.insemitters import InsEmitterOptions, live_ins_emitter
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.player import Pacing, PlayResult, play_emitters
from sarmoco.sim.transports import FileLink, Link, PtyLink, TcpServerLink, UdpOutLink
from tests.drivers.mapbounds import observe_map_bounds
from tests.sim.emit_common import play_fast, tiny_run

CLOCK = Faults(clock_offset_s=0.2, clock_drift_ppm=3.0)


def feed(faults: Faults = CLOCK) -> InsFeed:
    run = tiny_run(clock_offset_s=faults.clock_offset_s, clock_drift_ppm=faults.clock_drift_ppm)
    return InsFeed.from_run(run, faults)


def live(em: MavlinkEmitter, url: str) -> tuple[list[Sample], PlayResult, dict[int, int]]:
    """Play in real time (pinned to the host clock) against the driver polling ``url``;
    also returns the bound stated when each boot time was mapped (ns)."""
    result: dict[str, PlayResult] = {}

    def player() -> None:
        pacing = Pacing(realtime=True, pin_to_host=True, lead_s=1.0)
        result["r"] = play_emitters([em], pacing, wait_s=10.0, linger_s=0.2)

    th = threading.Thread(target=player)
    if url.startswith("udpin"):
        src = MavlinkSource(url)
        bounds = observe_map_bounds(src)
        th.start()
    else:
        th.start()
        src = MavlinkSource(url)
        bounds = observe_map_bounds(src)
    out: list[Sample] = []
    while th.is_alive():
        out += src.poll(0.02)
    out += src.poll(0.05)
    th.join()
    em.close()
    return out, result["r"], bounds


def by_index(em: MavlinkEmitter, samples: list[Sample], kind: type) -> tuple[np.ndarray, list]:
    """Feed index of each decoded sample of ``kind`` (matched on the boot time)."""
    boot_ms = np.round(em.feed.uptime_ns / 1e6).astype(np.int64)
    picked = [s for s in samples if isinstance(s, kind)]
    idx = np.searchsorted(boot_ms, [s.device_time_ns // 1_000_000 for s in picked])
    assert np.array_equal(boot_ms[idx], [s.device_time_ns // 1_000_000 for s in picked])
    return idx, picked


def check_values(
    em: MavlinkEmitter, samples: list[Sample]
) -> tuple[np.ndarray, np.ndarray, list[Sample]]:
    """Compare values (float32 on the wire); return feed indices, time errors (ns) and the
    velocity samples they belong to."""
    f = em.feed
    iv, vel = by_index(em, samples, VelocitySample)
    ia, att = by_index(em, samples, AttitudeSample)
    assert vel and att
    np.testing.assert_allclose([s.vel_ned for s in vel], f.vel_ned[iv], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose([s.pos_ned for s in vel], em.pos_ned[iv], rtol=1e-6, atol=1e-5)
    q = np.array([s.quat for s in att])
    np.testing.assert_allclose(q * np.sign(q[:, :1] * f.quat[ia, :1]), f.quat[ia], atol=1e-6)
    t = np.array([s.t_gps_ns for s in vel])
    return iv, t - (f.t_ns[iv] + em.wire.shift_ns), vel


def test_tlog_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "nav.tlog"
    rates = {"LOCAL_POSITION_NED": 200.0, "ATTITUDE_QUATERNION": 200.0, "SYSTEM_TIME": 5.0}
    em = MavlinkEmitter(FileLink(path), feed(), rates_hz=rates)
    play_fast(em)
    em.close()
    src = MavlinkSource(str(path))
    samples: list[Sample] = []
    while not src.eof:
        samples += src.poll()
    iv, err, _ = check_values(em, samples)
    assert iv.size == em.feed.t_ns.size  # every sample, at the INS rate
    # SYSTEM_TIME maps the boot clock to GPS time: within the stated bound, and in fact ~1 µs
    assert np.abs(err).max() <= src.time_bound_ns
    assert np.abs(err).max() <= 2_000
    # (drops are not checked: pymavlink reads 5 messages ahead when it opens a .tlog and
    # counts the rewind as a sequence gap of 251, reported to the drivers' owner)
    assert src.counters.crc_errors == 0 and src.counters.parse_errors == 0


def test_udp_live_timesync_and_rates() -> None:
    port = free_udp_port()
    em = MavlinkEmitter(UdpOutLink("127.0.0.1", port), feed())
    samples, result, bounds = live(em, f"udpin:127.0.0.1:{port}")
    # the driver asked for its rates; we obeyed (50 Hz of a 200 Hz INS: every 4th sample)
    assert em.answered["SET_MESSAGE_INTERVAL"] == len(DAEMON_RATES)
    assert em.rates_hz["LOCAL_POSITION_NED"] == pytest.approx(DAEMON_RATES["LOCAL_POSITION_NED"])
    assert em.answered["TIMESYNC"] >= 3
    iv, err, vel = check_values(em, samples)
    assert np.all(em.feed.index[iv] % 4 == 0)
    assert iv.size >= em.feed.t_ns.size // 4 - 2
    assert result.wire.shift_ns != 0  # pinned to the host clock
    # every GPS time is within the bound the driver stated when it mapped it, and once
    # TIMESYNC has settled that bound is well under the 20 ms a loopback allows
    stated = np.array([bounds[s.device_time_ns] for s in vel])
    late, late_bound = np.abs(err[iv.size // 2 :]), stated[iv.size // 2 :]
    print(  # the README's figures (pytest -s)
        f"\nlive MAVLink/UDP, second half: GPS time error median {np.median(late) / 1e3:.0f} µs, "
        f"max {late.max() / 1e3:.0f} µs; stated bound median {np.median(late_bound) / 1e3:.0f} µs"
    )
    assert np.all(np.abs(err) <= stated), (np.abs(err) - stated).max()
    assert late_bound.max() < 20_000_000


@pytest.mark.parametrize("kind", ["tcp", "pty"])
def test_stream_links(kind: str) -> None:
    link: Link = TcpServerLink("127.0.0.1", 0) if kind == "tcp" else PtyLink()
    url = (
        f"tcp:127.0.0.1:{link.describe()['listen'].split(':')[1]}"
        if kind == "tcp"
        else link.describe()["path"]
    )
    em = MavlinkEmitter(link, feed())
    samples, _, bounds = live(em, url)
    iv, err, vel = check_values(em, samples)
    assert iv.size >= em.feed.t_ns.size // 4 - 2
    stated = np.array([bounds[s.device_time_ns] for s in vel])
    assert np.all(np.abs(err) <= np.maximum(stated, 1_000_000)), (np.abs(err) - stated).max()


def test_loss_and_corruption_are_counted(tmp_path: Path) -> None:
    path = tmp_path / "bad.tlog"
    rates = {"LOCAL_POSITION_NED": 200.0, "ATTITUDE_QUATERNION": 200.0, "SYSTEM_TIME": 5.0}
    em = MavlinkEmitter(
        FileLink(path), feed(), rates_hz=rates, faults=PacketFaults(loss=0.03, corrupt=0.03), seed=4
    )
    play_fast(em)
    em.close()
    src = MavlinkSource(str(path))
    while not src.eof:
        src.poll()
    c, injected = src.counters, em.injector.counts
    assert injected.lost > 5 and injected.corrupted > 5
    sent = sum(em.sent.values())
    # a corrupted packet is a CRC or parse error, except a flip in the high bytes of the
    # 24-bit message id: pymavlink cannot check the CRC of an unknown id and returns it
    assert sent - injected.lost - injected.corrupted <= c.frames <= sent - injected.lost
    assert c.frames + c.crc_errors + c.parse_errors >= sent - injected.lost - 2
    samples_lost = sent - injected.lost - c.frames
    assert c.drops >= injected.lost + samples_lost


def test_a_second_mavlink_system_is_put_on_mavlink_links_only() -> None:
    """``--fault mavlink-rogue=ID`` reaches the simulated autopilot of a MAVLink link, and
    is refused, by name, on an SBG link (which has no systems to add one to)."""
    options = InsEmitterOptions(None, 0, 1, rogue_system=42)
    em = live_ins_emitter("mavlink:pty", feed(), options)
    try:
        assert isinstance(em, MavlinkEmitter) and em._rogue is not None
    finally:
        em.close()
    for spec in ("sbg:pty", "sbg-can:slcan-pty"):
        with pytest.raises(ConfigError, match="mavlink-rogue=42: the INS link is sbg"):
            live_ins_emitter(spec, feed(), options)
