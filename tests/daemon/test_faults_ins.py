"""INS faults (and the combined case) through the real processes: ``sarmoco sim --serve`` into
``sarmoco run`` over MAVLink/UDP and VITA/UDP, ku-vehicle x0.1 (465 pulses, 2.66 s, every
target's aperture spans the run).

- **Combined**: radar loss 2 %, radar bit flips 1 %, an INS dropout of 0.3 s at 1.2 s
  (mid-aperture): exit 0, the three targets' azimuth PSLR printed and held to 1 dB of the
  unweighted sinc's -13.26 dB (-7.0 to -7.2 dB when the case was first measured). The
  pulses of the silence (shorter than ``ins.bridge_gap_s``) are focused with navigation
  bridged across it and flagged ``NAV_BRIDGED`` in the store, none ``NAV_UNUSABLE``
  (blanked instead, an 11 % hole mid-aperture, they gave -5.0 to -5.2 dB).
- **INS clock and dropouts**: dropouts of 10 ms at 0.5 s and 1.0 s at 1.5 s, the INS
  clock stepping by 0.2 s at 1.0 s and drifting by 100 ppm: exit 0; no pulse before the
  step is flagged, the 10 ms silence (two INS samples at 200 Hz) is bridged, and most
  pulses of the 1 s silence are flagged ``NAV_UNUSABLE`` (not focused with extrapolated
  navigation). The step moves the INS stamps 0.2 s ahead: the 0.2 s hole it leaves in them
  at 1.0 s is bridged (its pulses ``NAV_BRIDGED``, 36 in the last run; before bridging they
  were flagged and blanked: 203 flagged then, 167 now).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.products.report import ReportSummary
from sarmoco.store.flags import NAV_UNUSABLE, PulseFlag
from sarmoco.store.reader import open_store
from tests.daemon.test_faults_wire import SINC_PSLR_DB

SCALE = 0.1
COMBINED = ("loss=0.02@radar", "corrupt=0.01@radar", "ins-dropout=1.2:0.3")
INS_FAULTS = (
    "ins-dropout=0.5:0.01",
    "ins-dropout=1.5:1.0",
    "clock-step=1.0:0.2",
    "clock-drift=100",
)


def _run(
    tmp_path_factory: pytest.TempPathFactory, name: str, faults: tuple[str, ...]
) -> tuple[Path, ReportSummary]:
    out = tmp_path_factory.mktemp(name)
    return out, run_loopback(out, SCALE, faults=faults)


def test_combined_loss_corruption_and_ins_dropout(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    out, summary = _run(tmp_path_factory, "combined", COMBINED)
    store = open_store(out / "run.zarr")
    assert store.attrs["complete"]
    faults = json.loads((out / "truth.json").read_text())["wire"]["links"]["radar"]
    pslr = [p["pslr_az_db"] for p in summary.image.points[:3]]
    flags = store.read("pulses", ["flags"])["flags"]
    bridged = (flags & np.uint32(PulseFlag.NAV_BRIDGED)) != 0
    print(f"combined: azimuth PSLR {pslr} dB; {bridged.sum()} pulses bridged; radar "
          f"{faults['stats']['faults']}; metrics "
          f"{store.attrs['metrics'] | {'tile_metrics': None}}")  # fmt: skip
    assert not (flags & np.uint32(NAV_UNUSABLE)).any()
    assert 0.25 * 175 < bridged.sum() <= 0.3 * 175 + 1  # the silence's pulses, less radar loss
    assert store.attrs["metrics"]["pulses_nav_bridged"] == bridged.sum()
    assert all(p <= SINC_PSLR_DB + 1.0 for p in pslr), pslr


def test_ins_clock_faults_and_dropouts(tmp_path_factory: pytest.TempPathFactory) -> None:
    out, summary = _run(tmp_path_factory, "insclock", INS_FAULTS)
    store = open_store(out / "run.zarr")
    assert store.attrs["complete"]
    truth = json.loads((out / "truth.json").read_text())
    got = store.read("pulses", ["t_ns", "flags"])
    t_s = (got["t_ns"] - truth["wire"]["shift_ns"] - truth["t0_ns"]) / 1e9
    t_s -= (np.asarray(truth["pulses"]["t_ns"][0]) - truth["t0_ns"]) / 1e9  # from the first
    flagged = (got["flags"] & np.uint32(NAV_UNUSABLE)) != 0
    bridged = (got["flags"] & np.uint32(PulseFlag.NAV_BRIDGED)) != 0
    in_long = (t_s >= 1.5) & (t_s < 2.5)
    in_short = (t_s >= 0.45) & (t_s < 0.56)
    pslr = [p["pslr_az_db"] for p in summary.image.points[:3]]
    print(f"INS faults: {flagged.sum()} of {t_s.size} pulses flagged, {flagged[in_long].sum()} "
          f"of {in_long.sum()} in the 1 s dropout, {flagged[in_short].sum()} around the 10 ms "
          f"one; flagged span {t_s[flagged].min() if flagged.any() else None} .. "
          f"{t_s[flagged].max() if flagged.any() else None} s; {bridged.sum()} bridged over "
          f"{t_s[bridged].min() if bridged.any() else None} .. "
          f"{t_s[bridged].max() if bridged.any() else None} s; azimuth PSLR {pslr} dB")  # fmt: skip
    assert not flagged[in_short].any()
    assert flagged[in_long].mean() > 0.5
    assert not flagged[t_s < 0.99].any()  # nothing before the clock step
    assert not bridged[(t_s < 0.99) | (t_s > 1.25)].any()  # only the step's hole
