"""Radar packet loss, at random and in bursts, through the real processes.

``sarmoco sim --serve --preset ku-vehicle --scale 0.1`` with ``--fault loss=0.1@radar``
(10 % of the VITA datagrams lost at random) or ``--fault burst=1:0.1@radar`` (every
datagram of the last 100 ms of each second lost: 10 % in bursts of ~17 pulses; and,
marked ``bench``, ``loss=0.01@radar``) into ``sarmoco run`` (UDP, MAVLink INS). The
daemon must exit 0, record every pulse that arrived, flag the pulse after each run of lost
ones ``LOST_BEFORE``, and focus the three targets with the lost pulses' slow-time slots
kept (zeros): then a loss of a fraction q of an aperture's N pulses changes a sidelobe by
at most the q·N unit phasors missing, so the azimuth PSLR is at most
``20 log10((s + q) / (1 - q))`` with s the unweighted sinc's sidelobe (-13.26 dB):
-9.06 dB for q = 0.1 whatever the pattern (q is measured: the most pulses lost within one
aperture). Random loss does far better on average (the missing phasors add up
incoherently). ``-s`` prints the numbers (README, "Faults, fuzzing and security").
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.store.flags import PulseFlag
from sarmoco.store.reader import open_store
from tests.daemon.test_faults_wire import SCALE, SINC_PSLR_DB


def worst_pslr_db(q: float) -> float:
    """Highest azimuth PSLR with a fraction ``q`` of the aperture's slots empty, dB."""
    s = 10 ** (SINC_PSLR_DB / 20)
    return float(20 * np.log10((s + q) / (1 - q)))


def aperture_loss(lost: npt.NDArray[np.bool_], scenario: dict[str, Any]) -> float:
    """The largest fraction of pulses ``lost`` (one flag per pulse sent) within one
    synthetic aperture (``aperture_s`` of the scenario at its PRF)."""
    n = min(lost.size, round(scenario["aperture_s"] * scenario["radar"]["prf_hz"]))
    return float(np.convolve(lost, np.ones(n), "valid").max() / n)


@pytest.mark.parametrize(
    ("fault", "what"),
    [
        ("loss=0.1@radar", "loss 10 %"),
        ("burst=1:0.1@radar", "bursts of 100 ms every 1 s"),
        pytest.param("loss=0.01@radar", "loss 1 %", marks=pytest.mark.bench),
    ],
)
def test_radar_loss_is_flagged_and_focused_around(tmp_path: Path, fault: str, what: str) -> None:
    summary = run_loopback(tmp_path, SCALE, faults=(fault,))  # raises unless exit 0
    truth = json.loads((tmp_path / "truth.json").read_text())
    stats = truth["wire"]["links"]["radar"]["stats"]
    faults = stats["faults"]
    sent = np.asarray(truth["pulses"]["t_ns"], dtype=np.int64) + truth["wire"]["shift_ns"]
    store = open_store(tmp_path / "run.zarr")
    assert store.attrs["complete"]
    got = store.read("pulses", ["t_ns", "flags"])
    assert np.isin(got["t_ns"], sent).all() and (np.diff(got["t_ns"]) > 0).all()
    arrived = np.isin(sent, got["t_ns"])
    # every pulse not lost is recorded (the simulator's loss count includes its few
    # context packets)
    pulses_lost = sent.size - int(arrived.sum())
    assert faults["lost"] - stats["contexts"] <= pulses_lost <= faults["lost"]
    assert store.attrs["metrics"]["pulses_late_dropped"] == 0
    # the first pulse after each run of lost ones carries LOST_BEFORE (the 4-bit count sees
    # every run shorter than 16; a context packet lost alone flags nothing)
    runs_before = np.flatnonzero(~arrived[:-1] & arrived[1:]) + 1
    flagged = (got["flags"] & np.uint32(PulseFlag.LOST_BEFORE)) != 0
    after_loss = np.isin(got["t_ns"], sent[runs_before])
    assert flagged[after_loss].mean() >= 0.9, (flagged[after_loss].sum(), after_loss.sum())
    q = aperture_loss(~arrived, truth["scenario"])
    pslr = [p["pslr_az_db"] for p in summary.image.points[:3]]
    print(
        f"radar {what}: {faults['lost']} of {faults['packets']} datagrams lost "
        f"({faults['burst_lost']} in bursts; {100 * q:.1f} % of an aperture's pulses), "
        f"{got['t_ns'].size} pulses recorded, "
        f"{int(flagged.sum())} flagged LOST_BEFORE; azimuth PSLR "
        f"{min(pslr):.2f} .. {max(pslr):.2f} dB (bound {worst_pslr_db(q):.2f} dB)"
    )
    assert max(pslr) <= worst_pslr_db(q), pslr
