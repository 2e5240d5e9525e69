"""The report's motion plot: the INS's LOS motion beside the autofocus's residual estimate
and the simulator's truth, on a real store (``sarmoco sim --out`` replayed by
``sarmoco replay``, turbulent motion, tactical INS, point targets)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image as PilImage

from sarmoco.app.truth import read_true_motion
from sarmoco.errors import RecorderError
from sarmoco.products.report import motion_comparison, write_report
from sarmoco.store.reader import open_store

PULSES = 320
"""Pulses simulated: about ten autofocus subapertures at ku-vehicle x0.1."""


@pytest.fixture(scope="module")
def replayed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Folder with ``sim/truth.json`` and ``replay.zarr``."""
    out = tmp_path_factory.mktemp("motion")
    py = [sys.executable, "-m", "sarmoco"]
    subprocess.run(
        [*py, "sim", "--preset", "ku-vehicle", "--scale", "0.1", "--motion", "turbulence",
         "--motion-seed", "1", "--ins-grade", "tactical", "--pulses", str(PULSES),
         "--out", str(out / "sim")],
        check=True, capture_output=True,
    )  # fmt: skip
    subprocess.run(
        [*py, "replay", "--config", str(out / "sim" / "sarmoco.toml"), "--radar",
         str(out / "sim" / "radar.vrt"), "--nav", str(out / "sim" / "nav.tlog"),
         "--out", str(out / "replay.zarr"), "--quiet"],
        check=True, capture_output=True,
    )  # fmt: skip
    return out


def test_truth_ins_and_autofocus_agree_on_the_residual(replayed: Path) -> None:
    """The true LOS displacement, integrated as the daemon integrates the INS's, follows the
    INS's to a drift (no Doppler rate sees it): what is left, and what the autofocus found
    on the point targets, are sub-millimetre against 6 cm of motion."""
    truth = read_true_motion(replayed / "sim" / "truth.json")
    panels, stats = motion_comparison(open_store(replayed / "replay.zarr"), truth)
    print({k: f"{1e3 * v:.3f} mm" for k, v in stats.items()})
    assert stats["ins_d_los_rms_m"] > 0.03
    assert stats["true_residual_rms_m"] < 1e-3
    assert stats["autofocus_residual_rms_m"] < 1e-3
    assert stats["autofocus_error_rms_m"] < 1e-3
    t_af, a_los = panels["LOS acceleration (m/s²)"]["autofocus a_los"]
    assert t_af.size >= 5 and np.all(np.diff(t_af) > 0) and np.all(np.isfinite(a_los))
    t, _ = panels["LOS displacement (m)"]["INS d_los"]
    assert t[0] == 0.0 and t[-1] <= t_af[-1] + 1.0


def test_report_draws_it_with_and_without_the_truth(replayed: Path, tmp_path: Path) -> None:
    summary = write_report(
        replayed / "replay.zarr",
        tmp_path / "r",
        truth=read_true_motion(replayed / "sim" / "truth.json"),
    )
    assert "true_residual_rms_m" in summary.motion_estimates
    picture = PilImage.open(tmp_path / "r" / "motion_estimates.png")
    assert picture.size[0] > 500
    assert 'src="motion_estimates.png"' in (tmp_path / "r" / "index.html").read_text()
    assert "LOS motion (rms)" in (tmp_path / "r" / "report.txt").read_text()
    panels, stats = motion_comparison(open_store(replayed / "replay.zarr"))
    assert "true_residual_rms_m" not in stats and "true d_los" not in panels["LOS displacement (m)"]
    bad = tmp_path / "truth.json"
    bad.write_text('{"pulses": {}}')
    with pytest.raises(RecorderError, match=r"wire\.shift_ns"):
        read_true_motion(bad)
