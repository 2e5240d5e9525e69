"""Fault injection: the switches parse, the injector does what it says, the drivers see it."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from sarmoco.drivers.mavlink import MavlinkSource
from sarmoco.drivers.samples import Sample, VelocitySample
from sarmoco.drivers.sbg import SbgFileSource
from sarmoco.drivers.source import Source
from sarmoco.errors import ConfigError
from sarmoco.sim.faults import (
    FaultCounts,
    Faults,
    PacketFaultInjector,
    PacketFaults,
    dropout_keep,
    parse_faults,
)
from sarmoco.sim.insclock import InsClock
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.outfiles import NAV_FILES, write_run
from tests.sim.emit_common import tiny_run


def test_parse_every_switch() -> None:
    f = parse_faults(
        ["loss=0.1@radar", "corrupt=0.02", "dup=0.05@ins", "reorder=0.3", "ins-dropout=0.5:0.05",
         "ins-dropout=1:0.2", "clock-offset=0.003", "clock-drift=20", "clock-step=1.5:-0.01"]
    )  # fmt: skip
    assert f.radar == PacketFaults(loss=0.1, corrupt=0.02, dup=0.0, reorder=0.3)
    assert f.ins == PacketFaults(loss=0.0, corrupt=0.02, dup=0.05, reorder=0.3)
    assert f.ins_dropouts_s == ((0.5, 0.05), (1.0, 0.2))
    assert (f.clock_offset_s, f.clock_drift_ppm, f.clock_steps_s) == (0.003, 20.0, ((1.5, -0.01),))
    assert parse_faults(None) == Faults()


@pytest.mark.parametrize(
    ("spec", "match"),
    [("loss", "KEY=VALUE"), ("loss=2", r"\[0, 1\]"), ("loss=0.1@gps", "link"),
     ("jitter=1", "unknown"), ("ins-dropout=1", "A:B"), ("ins-dropout=1:0", "duration"),
     ("clock-drift=fast", "number"), ("burst=0.1:1", "LENGTH < EVERY"),
     ("burst=1:0.1@gps", "link")],
)  # fmt: skip
def test_parse_errors_name_the_switch(spec: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_faults([spec])


def inject(faults: PacketFaults, n: int, seed: int = 0) -> tuple[list[bytes], FaultCounts]:
    inj = PacketFaultInjector(faults, seed)
    out: list[bytes] = []
    for k in range(n):
        inj.send(k.to_bytes(4, "big") * 4, out.append)
    inj.flush(out.append)
    return out, inj.counts


def test_no_fault_is_a_pass_through() -> None:
    out, counts = inject(PacketFaults(), 100)
    assert out == [k.to_bytes(4, "big") * 4 for k in range(100)]
    assert counts == FaultCounts(packets=100)


@pytest.mark.parametrize("kind", ["loss", "corrupt", "dup", "reorder"])
def test_rates_match_the_probability(kind: str) -> None:
    n, p = 20000, 0.05
    _, counts = inject(PacketFaults(**{kind: p}), n, seed=7)
    got = {"loss": counts.lost, "corrupt": counts.corrupted, "dup": counts.duplicated,
           "reorder": counts.reordered}[kind]  # fmt: skip
    # reordering holds one packet at a time, so its rate is a little below p
    assert abs(got - n * p) < 5 * math.sqrt(n * p * (1 - p)) + (
        n * p * p if kind == "reorder" else 0
    )


def test_each_fault_does_what_it_says() -> None:
    sent = [k.to_bytes(4, "big") * 4 for k in range(5000)]
    out, counts = inject(PacketFaults(loss=0.05, corrupt=0.05, dup=0.05, reorder=0.05), 5000, 3)
    assert len(out) == 5000 - counts.lost + counts.duplicated
    intact = [p for p in out if p in set(sent)]
    damaged = [p for p in out if p not in set(sent)]
    # a corrupted packet differs from one sent packet by exactly one bit
    for p in damaged:
        words = [p[i : i + 4] for i in range(0, 16, 4)]
        k = int.from_bytes(max(words, key=words.count), "big")  # three of four words intact
        flips = sum(bin(a ^ b).count("1") for a, b in zip(p, sent[k], strict=True))
        assert flips == 1
    assert len(damaged) <= counts.corrupted * 2  # (a corrupted packet may be duplicated)
    keys = [int.from_bytes(p[8:12], "big") for p in intact]
    assert sum(1 for a, b in itertools.pairwise(keys) if b < a) <= counts.reordered


def test_loss_bursts_drop_every_packet_in_their_window() -> None:
    """``burst=1:0.1@radar``: packets every 5 ms for 3.5 s lose exactly those in the last
    100 ms of each second from the first packet (3 bursts of 20), and nothing else; the
    other links are untouched."""
    f = parse_faults(["burst=1:0.1@radar"])
    assert f.radar == PacketFaults(burst_every_s=1.0, burst_s=0.1) and not f.ins.any
    inj = PacketFaultInjector(f.radar, seed=0)
    out: list[bytes] = []
    t0 = 10**18
    for k in range(700):
        inj.send(k.to_bytes(4, "big"), out.append, t0 + k * 5_000_000)
    got = {int.from_bytes(p, "big") for p in out}
    lost = sorted(set(range(700)) - got)
    assert lost == [k for s in (1, 2, 3) for k in range(200 * s - 20, 200 * s)]
    assert inj.counts.lost == inj.counts.burst_lost == 60


def test_same_seed_same_faults() -> None:
    f = PacketFaults(loss=0.1, corrupt=0.1, dup=0.1, reorder=0.1)
    assert inject(f, 2000, seed=5) == inject(f, 2000, seed=5)
    assert inject(f, 2000, seed=5)[0] != inject(f, 2000, seed=6)[0]


def test_dropout_mask() -> None:
    t = np.arange(0, 1_000_000_000, 5_000_000, dtype=np.int64) + 10**18
    keep = dropout_keep(t, 10**18, ((0.1, 0.05), (0.9, 1.0)))
    gone = t[~keep] - 10**18
    assert gone.min() == 100_000_000 and (gone < 150_000_000).sum() == 10
    assert (gone >= 900_000_000).sum() == 20


def test_ins_clock_agrees_with_the_ins_model() -> None:
    faults = Faults(clock_offset_s=0.25, clock_drift_ppm=-30.0, clock_steps_s=((0.05, 0.002),))
    run = tiny_run(clock_offset_s=0.25, clock_drift_ppm=-30.0)
    clock = InsClock.from_faults(run.scenario.t0_ns, run.t0_ns, faults)
    ticks = clock.sample_uptime_ns(run.ins.t_device_ns, run.ins.nav.t_ns)
    direct = np.array([clock.uptime_ns(int(t)) for t in run.ins.nav.t_ns])
    assert np.abs(ticks - direct).max() <= 1  # ns
    after = run.ins.nav.t_ns >= run.t0_ns + 50_000_000
    np.testing.assert_array_equal(np.diff(ticks)[~after[1:] | after[:-1]] % 1_000_000, 0)
    # ticks are uniform on the device clock (5 ms); the step adds its 2 ms once
    assert np.all(np.diff(ticks)[after[1:] & ~after[:-1]] == 5_000_000 + 2_000_000)


def drain(src: Source) -> list[Sample]:
    out: list[Sample] = []
    while not src.eof:
        out += src.poll()
    return out


def test_ins_dropout_is_a_silence_on_every_nav_link(tmp_path: Path) -> None:
    faults = parse_faults(["ins-dropout=0.03:0.05"])
    run = tiny_run()
    truth = write_run(run, faults, tmp_path, nav=("mavlink", "sbg"))
    a, b = run.t0_ns + 30_000_000, run.t0_ns + 80_000_000
    period = round(1e9 / InsFeed.from_run(run, faults).rate_hz)
    for src in (
        MavlinkSource(str(tmp_path / NAV_FILES["mavlink"])),
        SbgFileSource(tmp_path / NAV_FILES["sbg"]),
    ):
        t = np.array([s.t_gps_ns for s in drain(src) if isinstance(s, VelocitySample)])
        assert not np.any((t >= a) & (t < b))
        gap = np.diff(t).max()
        assert abs(gap - (b - a + period)) <= period  # the silence, and nothing else
        assert t.size == truth["wire"]["ins_samples_sent"]
