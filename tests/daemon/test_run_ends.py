"""Ends of runs focus like the middle (README issue 10 item 8), through the daemon.

``bench/run_ends.py`` at three noise seeds: ku-vehicle ×0.1 flown with a real ArduPilot
log's motion, tactical INS, nine targets (start, middle and end of the run × three ranges;
the first aperture starts at the run's first pulse, the last group leaves the beam 0.4 s
before the run ends), written as ``.vrt``/``.tlog`` and replayed with the autofocus on.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.run_ends import one


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_end_and_start_targets_focus_like_the_middle(seed: int, tmp_path: Path) -> None:
    """Every start and end target's azimuth PSLR is within 0.3 dB of the middle targets'
    mean (or better), and every target's at most -12.5 dB.

    Measured (dB, start / middle / end, three ranges each):
    seed 0: -12.97 -12.86 -12.97 / -13.12 -13.16 -13.12 / -13.32 -13.17 -13.19;
    seed 1: -13.38 -13.59 -13.42 / -12.94 -13.15 -12.90 / -13.04 -13.14 -12.92;
    seed 2: -13.09 -13.20 -13.20 / -12.72 -12.70 -12.75 / -12.82 -12.72 -12.71.
    Before map drift tapered the looks of lines holding several scatterers, the end targets
    were -12.0..-12.3 dB at seeds 1 and 2, a dB under the middle (seed 0 was saved only by
    the guard leaving the run's body uncorrected).
    """
    start, middle, end = one(seed, along_track=True, autofocus=True, out=tmp_path)
    print(f"seed {seed}: start {start} middle {middle} end {end} dB")
    bar = float(np.mean(middle)) + 0.3
    for pslr in [*start, *end]:
        assert pslr <= bar, (start, middle, end)
    for pslr in [*start, *middle, *end]:
        assert pslr <= -12.5, (start, middle, end)
