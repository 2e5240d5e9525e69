"""The simulated SBG INS: sbgECom round trips through a pseudo-terminal and a file."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from sarmoco.drivers.samples import AttitudeSample, EventSample, Sample, VelocitySample
from sarmoco.drivers.sbg import SbgFileSource, SbgSerialSource
from sarmoco.drivers.source import Source
from sarmoco.geodesy import ned_to_geodetic
from sarmoco.sim.emit_sbg import SbgEmitter
from sarmoco.sim.faults import Faults, PacketFaults
from sarmoco.sim.insfeed import GEODETIC_ORIGIN, InsFeed
from sarmoco.sim.transports import FileLink, Link, PtyLink
from tests.sim.emit_common import play_fast, tiny_run

DRIFT = Faults(clock_offset_s=0.37, clock_drift_ppm=2.0)
"""A free-running INS clock (offset and a realistic rate error)."""
FAST_DRIFT = Faults(clock_offset_s=-0.2, clock_drift_ppm=40.0)


def make(link: Link, ins: Faults = DRIFT, **kw: object) -> SbgEmitter:
    run = tiny_run(clock_offset_s=ins.clock_offset_s, clock_drift_ppm=ins.clock_drift_ppm)
    return SbgEmitter(link, InsFeed.from_run(run, ins), **kw)  # type: ignore[arg-type]


def drain(src: Source, stop: threading.Event | None = None) -> list[Sample]:
    out: list[Sample] = []
    idle = 0
    while not src.eof and idle < 10:
        got = src.poll(0.05)
        out += got
        idle = idle + 1 if not got and (stop is None or stop.is_set()) else 0
    return out


def check(em: SbgEmitter, samples: list[Sample], settled_after_ns: int = 0) -> None:
    feed = em.feed
    vel = [s for s in samples if isinstance(s, VelocitySample)]
    att = [s for s in samples if isinstance(s, AttitudeSample)]
    ev = [s for s in samples if isinstance(s, EventSample)]
    assert len(vel) == len(att) == feed.t_ns.size
    t_vel = np.array([s.t_gps_ns for s in vel])
    # GPS time recovered from the device clock and UTC_TIME, to 1 µs
    settled = feed.t_ns >= settled_after_ns
    assert np.abs(t_vel - feed.t_ns)[settled].max() <= 1000
    np.testing.assert_allclose([s.vel_ned for s in vel], feed.vel_ned, rtol=1e-6, atol=1e-6)
    q = np.array([s.quat for s in att])
    q *= np.sign(q[:, :1]) * np.sign(feed.quat[:, :1])
    np.testing.assert_allclose(q, feed.quat, atol=1e-6)
    lla = np.array([s.lat_lon_alt for s in vel], dtype=np.float64)
    if feed.pos_ned is not None:
        assert np.allclose(lla, ned_to_geodetic(feed.pos_ned, GEODETIC_ORIGIN), atol=1e-6)
    t_ev = np.array([s.t_gps_ns for s in ev])
    assert t_ev.size == feed.pulse_t_ns.size
    assert np.abs(t_ev - feed.pulse_t_ns)[feed.pulse_t_ns >= settled_after_ns].max() <= 1000


def test_file_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "ins.sbg"
    em = make(FileLink(path))
    play_fast(em)
    em.close()
    with SbgFileSource(path) as src:
        samples = drain(src)
        assert src.counters.crc_errors == 0 and src.counters.parse_errors == 0
    check(em, samples)
    assert em.sent["UTC_TIME"] >= 3


def test_fast_drift_is_tracked_once_the_skew_is_known(tmp_path: Path) -> None:
    path = tmp_path / "drift.sbg"
    em = make(FileLink(path), FAST_DRIFT, utc_period_s=0.05)
    play_fast(em)
    em.close()
    with SbgFileSource(path) as src:
        samples = drain(src)
    # the driver estimates the skew from its third UTC_TIME on (offset only before)
    check(em, samples, settled_after_ns=int(em.feed.t_ns[2 * em.utc_every]))


def test_pty_round_trip() -> None:
    link = PtyLink()
    em = make(link, attitude="euler")
    src = SbgSerialSource(link.path)
    done = threading.Event()

    def player() -> None:
        play_fast(em, wait_s=5.0)  # waits until the daemon has the pty open
        done.set()

    th = threading.Thread(target=player)
    th.start()
    samples = drain(src, done)
    th.join(10)
    src.close()
    em.close()
    check(em, samples)


def test_clock_step_is_followed(tmp_path: Path) -> None:
    faults = Faults(clock_steps_s=((0.05, 0.25),))
    path = tmp_path / "step.sbg"
    em = make(FileLink(path), faults, utc_period_s=0.01)
    play_fast(em)
    em.close()
    with SbgFileSource(path) as src:
        vel = [s for s in drain(src) if isinstance(s, VelocitySample)]
    t = np.array([s.t_gps_ns for s in vel])
    err = np.abs(t - em.feed.t_ns[: t.size])
    # the samples right after the step are mis-mapped until the fit follows the new clock
    good = err <= 1000
    assert good.mean() > 0.6, err


def test_crc_catches_every_corrupted_frame(tmp_path: Path) -> None:
    path = tmp_path / "bad.sbg"
    em = make(FileLink(path), DRIFT, faults=PacketFaults(corrupt=0.05), seed=11)
    play_fast(em)
    em.close()
    with SbgFileSource(path) as src:
        drain(src)
        c = src.counters
    n_sent = sum(em.sent.values())
    assert em.injector.counts.corrupted > 5
    assert c.frames == n_sent - em.injector.counts.corrupted
    assert c.crc_errors + c.parse_errors >= em.injector.counts.corrupted - 2  # (sync-byte hits)
