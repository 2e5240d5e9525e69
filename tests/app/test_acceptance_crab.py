"""A crabbed flight through the independent end-to-end check in ``../shared/acceptance``.

``run_blackbox.py --crab 6`` builds a stripmap run whose body is yawed 6° against its
ground track (a crosswind): the beam, fixed to the body, is squinted and its Doppler
centroid aliased at the pulse rate. The replay through the real daemon must focus every
target to PSLR <= -12.5 dB and IRW <= 1.1 x theory in both axes (the harness's verdict).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
HARNESS = REPO.parent / "shared" / "acceptance" / "run_blackbox.py"


@pytest.mark.xfail(
    strict=True,
    reason="every target is found, azimuth IRW within 1.07 x theory, but azimuth PSLR to "
    "-7.7 dB (T3): the INS error is left in (with an error-free INS and the autofocus off "
    "every target passes, -13.25 dB, IRW 1.01 x)",
)
def test_crab_6_deg_focuses_every_target(tmp_path: Path) -> None:
    if not HARNESS.is_file():
        pytest.fail(f"acceptance harness not found at {HARNESS}")
    run = subprocess.run(
        [sys.executable, str(HARNESS), "--crab", "6", "--workdir", str(tmp_path / "crab6")],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    verdict = [line for line in run.stdout.splitlines() if line.startswith("VERDICT")]
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert verdict and verdict[0].startswith("VERDICT: PASS")
