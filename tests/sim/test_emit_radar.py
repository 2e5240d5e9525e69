"""The simulated radar: VITA 49.2 round trips through a file, UDP and TCP, decoded by the driver."""

from __future__ import annotations

import itertools
import threading
from pathlib import Path

import numpy as np
import pytest

from sarmoco.drivers.radar import RadarFileSource, RadarSource, RadarTcpSource, RadarUdpSource
from sarmoco.drivers.samples import EchoPacket
from sarmoco.drivers.vita49 import PayloadFormat, VitaDecoder
from sarmoco.errors import ConfigError
from sarmoco.sim.emit_radar import INT16_PEAK, RadarEmitter
from sarmoco.sim.faults import PacketFaults
from sarmoco.sim.transports import FileLink, Link, TcpServerLink, UdpOutLink
from tests.sim.emit_common import play_fast, tiny_run


def emitter(
    link: Link, payload: PayloadFormat = "int16", faults: PacketFaults | None = None, seed: int = 0
) -> RadarEmitter:
    run = tiny_run()
    return RadarEmitter(
        link, run.scenario.radar, run.t_ns, run.echo, payload=payload, stream_id=7,
        faults=faults, seed=seed,
    )  # fmt: skip


def read_all(
    src: RadarSource, n_samples: int, want: int, rounds: int = 200
) -> tuple[list[EchoPacket], np.ndarray]:
    out = np.zeros((4 * want + 16, n_samples), np.complex64)
    got: list[EchoPacket] = []
    for _ in range(rounds):
        if len(got) >= want or src.eof:
            break
        got += src.read_into(out[len(got) :], 0.05)
    return got, out[: len(got)]


def check_exact(em: RadarEmitter, got: list[EchoPacket], rows: np.ndarray) -> None:
    run = tiny_run()
    assert [p.t_gps_ns for p in got] == run.t_ns.tolist()  # transmit time, to the ns
    assert {p.stream_id for p in got} == {7}
    for k, (p, row) in enumerate(zip(got, rows, strict=True)):
        assert p.packet_count == k % 16 and p.valid_data and p.lost_before == 0
        sent = em.wire_samples(k)
        want = sent[0::2] + 1j * sent[1::2] if em.payload == "int16" else sent
        np.testing.assert_array_equal(row, want)
    if em.payload == "int16":
        # the scale maps the raw echo onto int16 to within rounding
        np.testing.assert_allclose(rows / em.iq_scale, run.echo, atol=0.5 / em.iq_scale * 1.5)
        assert np.abs(rows.view(np.float32)).max() == pytest.approx(INT16_PEAK, abs=1)


@pytest.mark.parametrize("payload", ["int16", "float32"])
def test_vrt_file_round_trip(tmp_path: Path, payload: PayloadFormat) -> None:
    path = tmp_path / "radar.vrt"
    em = emitter(FileLink(path), payload)
    play_fast(em)
    em.close()
    n = tiny_run().echo.shape[1]
    dec = VitaDecoder(n, payload)
    with RadarFileSource(path, dec) as src:
        got, rows = read_all(src, n, len(tiny_run().t_ns))
    check_exact(em, got, rows)
    ctx = dec.context[7]
    radar = tiny_run().scenario.radar
    # the digitised band (VITA 49.2 CIF0 bandwidth): a dechirp receiver's beat band
    assert radar.receive == "dechirp" and em.digitised_band_hz == radar.sample_rate_hz
    assert ctx.bandwidth_hz == pytest.approx(em.digitised_band_hz, abs=1e-6)
    assert ctx.rf_reference_hz == pytest.approx(radar.carrier_hz, abs=1e-6)
    assert ctx.sample_rate_hz == pytest.approx(radar.sample_rate_hz, abs=1e-6)
    assert dec.counters.parse_errors == 0 and dec.counters.drops == 0


def test_udp_round_trip() -> None:
    n = tiny_run().echo.shape[1]
    dec = VitaDecoder(n, "int16")
    with RadarUdpSource("127.0.0.1", 0, dec) as src:
        em = emitter(UdpOutLink("127.0.0.1", src.address[1]))
        play_fast(em)
        em.close()
        got, rows = read_all(src, n, len(tiny_run().t_ns), rounds=10)
    check_exact(em, got, rows)


def test_tcp_round_trip() -> None:
    n = tiny_run().echo.shape[1]
    link = TcpServerLink("127.0.0.1", 0)
    em = emitter(link)
    dec = VitaDecoder(n, "int16")
    result: dict[str, tuple[list[EchoPacket], np.ndarray]] = {}

    def reader() -> None:
        with RadarTcpSource("127.0.0.1", link.address[1], dec) as src:
            result["got"] = read_all(src, n, len(tiny_run().t_ns))

    th = threading.Thread(target=reader)
    th.start()
    play_fast(em, wait_s=5.0)  # waits for the daemon's connection
    em.close()  # EOF ends the reader
    th.join(10)
    got, rows = result["got"]
    check_exact(em, got, rows)


def test_udp_refuses_oversize_pulses() -> None:
    run = tiny_run()
    echo = np.zeros((2, 20000), np.complex64)
    with pytest.raises(ConfigError, match="datagram"):
        RadarEmitter(UdpOutLink("127.0.0.1", 9), run.scenario.radar, run.t_ns[:2], echo)


def test_loss_is_seen_by_the_packet_count(tmp_path: Path) -> None:
    path = tmp_path / "lossy.vrt"
    em = emitter(FileLink(path), faults=PacketFaults(loss=0.2), seed=5)
    play_fast(em)
    em.close()
    run = tiny_run()
    n = run.echo.shape[1]
    dec = VitaDecoder(n, "int16")
    with RadarFileSource(path, dec) as src:
        got, _ = read_all(src, n, len(run.t_ns))
    received = [run.t_ns.tolist().index(p.t_gps_ns) for p in got]
    missing = sorted(set(range(len(run.t_ns))) - set(received))
    assert em.injector.counts.lost >= len(missing) > 0
    inside = [k for k in missing if received[0] < k < received[-1]]
    assert dec.counters.drops == len(inside)  # every gap of < 16 packets is counted
    assert sum(p.lost_before for p in got) == len(inside)


def test_duplicates_and_reordering_arrive_as_injected(tmp_path: Path) -> None:
    path = tmp_path / "dup.vrt"
    em = emitter(FileLink(path), faults=PacketFaults(dup=0.1, reorder=0.1), seed=2)
    play_fast(em)
    em.close()
    run = tiny_run()
    n = run.echo.shape[1]
    dec = VitaDecoder(n, "int16")
    with RadarFileSource(path, dec) as src:
        got, _ = read_all(src, n, 2 * len(run.t_ns))
    counts = em.injector.counts
    assert counts.duplicated > 0 and counts.reordered > 0
    t = [p.t_gps_ns for p in got]
    assert 0 < len(t) - len(run.t_ns) <= counts.duplicated  # (contexts may be duplicated too)
    assert sorted(set(t)) == run.t_ns.tolist()
    backwards = sum(1 for a, b in itertools.pairwise(t) if b < a)
    assert 0 < backwards <= counts.reordered


@pytest.mark.parametrize("payload", ["int16", "float32"])
def test_pregenerated_wire_samples_play_the_same_packets(
    tmp_path: Path, payload: PayloadFormat
) -> None:
    """``sarmoco sim --pregenerate``: the packets played from the rendered file are those of
    the echoes rendered as they are played, through the driver's decoder."""
    em = emitter(FileLink(tmp_path / "r.vrt"), payload)
    want = np.stack([em.wire_samples(k) for k in range(em.t_ns.size)])
    em.pregenerate(tmp_path / "wire.npy")
    em.echo = np.zeros_like(em.echo)  # playing must not read the echoes again
    play_fast(em)
    em.close()
    n = tiny_run().echo.shape[1]
    with RadarFileSource(tmp_path / "r.vrt", VitaDecoder(n, payload)) as src:
        got, rows = read_all(src, n, em.t_ns.size)
    check_exact(em, got, rows)
    np.testing.assert_array_equal(np.load(tmp_path / "wire.npy"), want)
