"""The INS protocol registry of :mod:`sarmoco.daemon.links`, on real files, a pty and a CAN bus.

Each registered protocol opens the simulator's recording of that protocol and decodes
every INS sample at its time; the live openers read the same bytes from a pseudo-terminal
(SBG) and a python-can virtual bus (SBG CAN). The registry, the configuration's allowed
``ins.protocol`` values and the simulator's emitters name the same protocols.
"""

from __future__ import annotations

import os
import subprocess
import sys
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

from sarmoco.daemon.config import Config, InsConfig, InsProtocol, describe_keys, parse_config
from sarmoco.daemon.links import INS_OPENERS, open_ins, open_radar
from sarmoco.drivers.can_source import CanLogSource, CanSource
from sarmoco.drivers.samples import Sample, VelocitySample
from sarmoco.drivers.sbg import SbgSerialSource
from sarmoco.drivers.source import Source
from sarmoco.drivers.vita49 import encode_context_packet, encode_signal_packet
from sarmoco.errors import ConfigError
from sarmoco.sim.faults import Faults
from sarmoco.sim.insemitters import INS_EMITTERS
from sarmoco.sim.outfiles import NAV_FILES, write_run
from tests.sim.emit_common import tiny_run

MAX_TIME_ERROR_NS = 2_000
"""Decoded INS time against the truth (the wire formats' resolution is 1 us), ns."""


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """The simulator's INS recordings of one small run, and its truth record."""
    out = tmp_path_factory.mktemp("links")
    return out, write_run(tiny_run(), Faults(), out)


def ins_config(protocol: str) -> Config:
    return Config(ins=InsConfig(protocol=protocol))


def velocities(src: Source, feed: Callable[[], bool] = lambda: False) -> list[VelocitySample]:
    """Poll ``src`` until its end (a file) or until ``feed`` has nothing left and it is idle."""
    got: list[Sample] = []
    idle = 0
    while not src.eof and idle < 20:
        more = src.poll(0.01)
        got += more
        fed = feed()
        idle = 0 if (more or fed) else idle + 1
    return [s for s in got if isinstance(s, VelocitySample)]


def assert_every_sample(vel: list[VelocitySample], truth: dict[str, Any]) -> None:
    t_true = np.array(truth["ins"]["t_ns"])
    assert len(vel) == t_true.size
    t_got = np.array([s.t_gps_ns for s in vel])
    assert np.abs(t_got - t_true).max() <= MAX_TIME_ERROR_NS


def test_the_registries_and_the_configuration_name_the_same_protocols() -> None:
    assert list(INS_OPENERS) == list(INS_EMITTERS) == list(typing.get_args(InsProtocol))
    row = next(r for r in describe_keys() if r["key"] == "ins.protocol")
    assert row["allowed"] == '"mavlink", "sbg", "sbg-can"' and row["type"] == "string"
    for name in INS_OPENERS:
        assert parse_config({"ins": {"protocol": name}}).ins.protocol == name


def test_the_configuration_loads_no_ins_driver() -> None:
    """The openers import their drivers when called: reading a configuration (which takes
    the protocol names from the registry) loads neither pymavlink nor python-can."""
    code = (
        "import sys\nimport sarmoco.daemon.config\n"
        "print(sorted(m for m in ('pymavlink', 'can', 'serial') if m in sys.modules))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


def test_an_unknown_protocol_is_a_config_error_naming_the_key() -> None:
    allowed = "'mavlink', 'sbg', 'sbg-can'"
    with pytest.raises(ConfigError, match=rf"^ins\.protocol: 'nmea' is not one of {allowed}$"):
        parse_config({"ins": {"protocol": "nmea"}})
    with pytest.raises(ConfigError, match=r"^ins\.protocol: 3 is not a string$"):
        parse_config({"ins": {"protocol": 3}})
    # a Config built in code skips the loader's check; the opener still names the key
    with pytest.raises(ConfigError, match=rf"^ins\.protocol: 'nmea' is not one of {allowed}$"):
        open_ins(ins_config("nmea"))


@pytest.mark.parametrize("protocol", list(INS_OPENERS))
def test_each_protocol_decodes_its_recording(
    recordings: tuple[Path, dict[str, Any]], protocol: str
) -> None:
    out, truth = recordings
    with open_ins(ins_config(protocol), str(out / NAV_FILES[protocol])) as src:
        vel = velocities(src)
    assert_every_sample(vel, truth)


def test_sbg_opens_a_serial_device(recordings: tuple[Path, dict[str, Any]]) -> None:
    """A ``/dev/...`` link is a serial port (here a pty) carrying the logged bytes."""
    out, truth = recordings
    data = (out / NAV_FILES["sbg"]).read_bytes()
    master, slave = os.openpty()
    chunks = [data[i : i + 512] for i in range(0, len(data), 512)]

    def feed() -> bool:
        if chunks:
            os.write(master, chunks.pop(0))
            return True
        return False

    try:
        with open_ins(ins_config("sbg"), os.ttyname(slave)) as src:
            assert isinstance(src, SbgSerialSource)
            vel = velocities(src, feed)
    finally:
        os.close(master)
        os.close(slave)
    assert_every_sample(vel, truth)


def test_sbg_can_opens_a_python_can_bus(recordings: tuple[Path, dict[str, Any]]) -> None:
    """``INTERFACE:CHANNEL``: the recorded frames sent on a python-can virtual bus."""
    out, truth = recordings
    frames = list(can.LogReader(str(out / NAV_FILES["sbg-can"])))
    with (
        open_ins(ins_config("sbg-can"), "virtual:test-links") as src,
        can.Bus(interface="virtual", channel="test-links") as bus,
    ):
        assert isinstance(src, CanSource) and not isinstance(src, CanLogSource)

        def feed() -> bool:
            for msg in frames[:64]:
                bus.send(msg)
            del frames[:64]
            return bool(frames)

        vel = velocities(src, feed)
    assert_every_sample(vel, truth)


@pytest.mark.parametrize(
    ("link", "reason"),
    [
        ("can0", "is not INTERFACE:CHANNEL or a CAN log file"),
        ("socketcand:127.0.0.1", "is not socketcand:HOST:PORT:CHANNEL"),
        ("socketcand:host:port:can0", "is not socketcand:HOST:PORT:CHANNEL"),
    ],
)
def test_a_can_link_that_does_not_parse_names_ins_link(link: str, reason: str) -> None:
    with pytest.raises(ConfigError, match=rf"^ins\.link: '{link}' {reason}$"):
        open_ins(ins_config("sbg-can"), link)


DECHIRP_RADAR = {
    "receive": "dechirp",
    "bandwidth_hz": 1.1e9,
    "sample_rate_hz": 40e6,
    "n_samples": 64,
    "pulse_width_s": 1e-4,
    "range_gate_delay_s": 6e-6,
}
"""A dechirp radar: a 1.1 GHz chirp, its beat band digitised as I/Q at 40 MHz."""

MATCHED_RADAR = {"bandwidth_hz": 750e6, "sample_rate_hz": 1e9, "range_gate_delay_s": 5.98e-6}
"""A pulsed-LFM radar: a 750 MHz chirp sampled as I/Q at 1 GHz."""


@pytest.mark.parametrize(
    ("radar", "reported_hz", "agrees"),
    [
        (DECHIRP_RADAR, 32e6, True),  # the digitiser's IF (beat) band
        (DECHIRP_RADAR, 1.1e9, False),  # the chirp's: no 40 MHz I/Q stream holds it
        (MATCHED_RADAR, 900e6, True),  # anti-alias band
        (MATCHED_RADAR, 600e6, False),  # cuts the chirp
    ],
)
def test_radar_context_is_checked_against_the_digitised_band(
    tmp_path: Path, radar: dict[str, Any], reported_hz: float, agrees: bool
) -> None:
    """The radar link of a configuration reads the context's Bandwidth as the band
    digitised in the stream: a dechirp digitiser reporting its IF band gets its pulses
    focused, one reporting a band the configured receiver cannot have gets them flagged."""
    cfg = parse_config(
        {
            "radar": {"n_samples": 64, **radar},
            "geometry": {"center_slant_range_m": 900.0, "height_m": 100.0},
            "imaging": {"swath_m": 5.0},
        }
    )
    t0 = 1_400_000_000_000_000_000
    vrt = tmp_path / "radar.vrt"
    context = encode_context_packet(
        0,
        t0,
        0,
        bandwidth_hz=reported_hz,
        rf_reference_hz=cfg.radar.carrier_hz,
        sample_rate_hz=cfg.radar.sample_rate_hz,
    )
    iq = np.ones(64, np.complex64)
    vrt.write_bytes(context + b"".join(encode_signal_packet(0, t0 + k, k, iq) for k in range(3)))
    rows = np.zeros((8, 64), np.complex64)
    with open_radar(cfg, str(vrt)) as src:
        got = src.read_into(rows)
    assert len(got) == 3
    assert [p.context_mismatch for p in got] == [not agrees] * 3
