"""`sarmoco sim --out DIR`: every file decodes with the drivers into what the truth says."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sarmoco.drivers.can_source import CanLogSource
from sarmoco.drivers.mavlink import MavlinkSource
from sarmoco.drivers.radar import RadarFileSource
from sarmoco.drivers.samples import EchoPacket, Sample, VelocitySample
from sarmoco.drivers.sbg import SbgFileSource
from sarmoco.drivers.source import Source
from sarmoco.drivers.vita49 import VitaDecoder
from sarmoco.errors import DataFileError
from sarmoco.sim.faults import Faults
from sarmoco.sim.outfiles import NAV_FILES, RADAR_FILE, TRUTH_FILE, write_run
from sarmoco.sim.player import Pacing
from tests.sim.emit_common import tiny_run


def drain(src: Source) -> list[Sample]:
    out: list[Sample] = []
    while not src.eof:
        out += src.poll()
    return out


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("run")
    truth = write_run(tiny_run(), Faults(), out)
    return out, truth


def test_files_and_truth(written: tuple[Path, dict]) -> None:
    out, truth = written
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [RADAR_FILE, TRUTH_FILE, *NAV_FILES.values()]
    )
    on_disk = json.loads((out / TRUTH_FILE).read_text())
    assert on_disk == json.loads(json.dumps(truth))
    assert on_disk["wire"]["shift_ns"] == 0
    assert on_disk["pulses"]["t_ns"] == tiny_run().t_ns.tolist()
    stats = on_disk["wire"]["links"]["radar"]["stats"]
    assert stats["pulses"] == len(tiny_run().t_ns) and stats["faults"]["lost"] == 0


def test_radar_file_matches_truth(written: tuple[Path, dict]) -> None:
    out, truth = written
    radar = truth["scenario"]["radar"]
    n = radar["n_samples"]
    dec = VitaDecoder(n, truth["wire"]["links"]["radar"]["payload"])
    rows = np.zeros((len(truth["pulses"]["t_ns"]) + 4, n), np.complex64)
    with RadarFileSource(out / RADAR_FILE, dec) as src:
        got: list[EchoPacket] = []
        while not src.eof:
            got += src.read_into(rows[len(got) :])
    assert [p.t_gps_ns for p in got] == truth["pulses"]["t_ns"]
    scale = truth["wire"]["links"]["radar"]["iq_scale"]
    np.testing.assert_allclose(rows[: len(got)] / scale, tiny_run().echo, atol=0.75 / scale)
    assert dec.context[0].rf_reference_hz == pytest.approx(radar["carrier_hz"])


@pytest.mark.parametrize("proto", list(NAV_FILES))
def test_nav_files_match_truth(written: tuple[Path, dict], proto: str) -> None:
    out, truth = written
    path = out / NAV_FILES[proto]
    src: Source
    if proto == "mavlink":
        src = MavlinkSource(str(path))
    elif proto == "sbg":
        src = SbgFileSource(path)
    else:
        src = CanLogSource(path)
    vel = [s for s in drain(src) if isinstance(s, VelocitySample)]
    t_true = np.array(truth["ins"]["t_ns"])
    v_true = np.array(truth["ins"]["vel_ned"])
    idx = np.searchsorted(t_true, [s.t_gps_ns for s in vel])
    idx = np.clip(idx, 0, t_true.size - 1)
    assert len(vel) == t_true.size  # every INS sample in every recording
    assert np.abs(np.array([s.t_gps_ns for s in vel]) - t_true).max() <= 2_000  # ns
    atol = 0.005 if proto == "sbg-can" else 1e-5  # CAN carries 0.01 m/s steps
    np.testing.assert_allclose([s.vel_ned for s in vel], v_true, atol=atol)


def test_fast_and_realtime_write_the_same_bytes(tmp_path: Path) -> None:
    run = tiny_run()
    faults = Faults(ins_dropouts_s=((0.02, 0.03),))
    write_run(run, faults, tmp_path / "fast", nav=("mavlink", "sbg"), seed=3)
    write_run(
        run, faults, tmp_path / "rt", nav=("mavlink", "sbg"), seed=3,
        pacing=Pacing(realtime=True, speed=4.0),
    )  # fmt: skip
    for name in (RADAR_FILE, NAV_FILES["mavlink"], NAV_FILES["sbg"]):
        assert (tmp_path / "fast" / name).read_bytes() == (tmp_path / "rt" / name).read_bytes()


def test_unknown_recording_is_refused(tmp_path: Path) -> None:
    with pytest.raises(DataFileError, match="unknown"):
        write_run(tiny_run(), Faults(), tmp_path, nav=("nmea",))
