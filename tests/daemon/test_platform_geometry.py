"""The platform as flown, through the whole daemon: lever arm, attitude, heading, look side.

``sarmoco sim --out`` writes a scaled ku-vehicle run whose motion and attitude are a real
ArduPilot flight (``flightlog``: the logged velocities straightened about the course, the
logged roll, pitch and yaw wander: a steady 18 deg bank and 2.8 deg of pitch motion over the
aperture) with the antenna 0.39 m from the INS; ``sarmoco replay`` focuses it from the raw
``.vrt`` and ``.tlog`` files with the configuration the simulator wrote. Headings in all four
quadrants, both look sides.

The INS is exact and the autofocus is off, so that what focuses the targets is the geometry
alone: the arm rotated by the attitude (the aligner's APC velocity) and the along-track
placement of the pulses. With the arm: azimuth PSLR -13.07 to -13.27 dB; with the arm's
rate dropped from the aligner: -11.66 to -12.01 dB, every case red (measured when this
test was last changed; `pytest -s` prints them).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from scipy.spatial.transform import Rotation

from tests.daemon.test_end_to_end import assert_focused, store_points

CASES = [(45.0, "right"), (135.0, "left"), (225.0, "right"), (315.0, "left")]


def _sarmoco(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "sarmoco", *args], check=True, capture_output=True)


@pytest.mark.parametrize(
    ("heading_deg", "look_side"), CASES, ids=[f"{h:.0f}-{s}" for h, s in CASES]
)
def test_lever_arm_attitude_heading_and_look_side_focus(
    tmp_path: Path, shared_data: Path, heading_deg: float, look_side: str
) -> None:
    tlog = shared_data / "mavlink" / "arduplane_quadplane_sitl.tlog"
    _sarmoco(
        "sim", "--preset", "ku-vehicle", "--scale", "0.05", "--motion", f"flightlog:{tlog}",
        "--ins-grade", "ideal", "--heading-deg", str(heading_deg), "--look-side", look_side,
        "--out", str(tmp_path),
    )  # fmt: skip
    truth = json.loads((tmp_path / "truth.json").read_text())
    arm = np.asarray(truth["scenario"]["lever_arm_m"])
    assert np.linalg.norm(arm) >= 0.3
    euler = Rotation.from_quat(np.asarray(truth["ins"]["quat"])[:, [1, 2, 3, 0]]).as_euler("ZYX")
    assert np.ptp(euler[:, 1]) >= math.radians(1.0)  # pitch motion over the run
    cfg_path = tmp_path / "sarmoco.toml"
    cfg = tomllib.loads(cfg_path.read_text())
    assert cfg["ins"]["lever_arm_m"] == list(arm) and cfg["geometry"]["look_side"] == look_side
    cfg["autofocus"]["enabled"] = False
    cfg.setdefault("mocomp", {})["along_track"] = True
    cfg_path.write_text(tomli_w.dumps(cfg))
    _sarmoco(
        "replay", "--config", str(cfg_path), "--radar", str(tmp_path / "radar.vrt"),
        "--nav", str(tmp_path / "nav.tlog"), "--out", str(tmp_path / "run.zarr"), "--quiet",
    )  # fmt: skip
    points = store_points(tmp_path / "run.zarr")
    print(  # shown with pytest -s: the README's numbers
        f"heading {heading_deg:.0f} deg, looking {look_side}: azimuth PSLR "
        + ", ".join(f"{p['pslr_az_db']:.2f}" for p in points[:3])
        + " dB"
    )
    assert_focused(tmp_path, points)
