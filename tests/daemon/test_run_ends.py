"""Ends of runs focus like the middle (README issue 10 item 8), through the daemon.

``bench/run_ends.py`` at three noise seeds: ku-vehicle ×0.1 flown with a real ArduPilot
log's motion, tactical INS, nine targets (start, middle and end of the run × three ranges;
the first aperture starts at the run's first pulse, the last group leaves the beam 0.4 s
before the run ends), written as ``.vrt``/``.tlog`` and replayed with the autofocus on.
Each seed is simulated and focused once (the module's ``runs`` fixture); the end and the
start targets are judged by separate tests.

Measured (dB, start / middle / end, three ranges each; ``mocomp.envelope_fraction`` 0.05):
seed 0: -12.78 -12.66 -12.80 / -13.13 -13.16 -13.09 / -13.32 -13.17 -13.19;
seed 1: -13.11 -13.33 -13.22 / -12.93 -13.14 -12.90 / -13.04 -13.14 -12.91;
seed 2: -12.71 -12.82 -12.83 / -12.71 -12.71 -12.77 / -12.82 -12.73 -12.71.
Before map drift tapered the looks of lines holding several scatterers, the end targets
were -12.0..-12.3 dB at seeds 1 and 2, a dB under the middle. With the former envelope
threshold (0.25 cell) seed 0's start targets were -12.97 -12.86 -12.97: the first 0.8 s of
the run (d_los under 5 cm) kept up to 10 % envelope loss, a taper over one side of their
aperture that happened to lower a sidelobe; their azimuth IRW is 1.00 × theory either way
and a wider squint tolerance (0.6°) does not help, so the cause is open.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.workloads.run_ends import one

SEEDS = [0, 1, 2]
Groups = list[list[float]]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Groups]:
    """Azimuth PSLR (dB) of the start, middle and end targets of every seed's run."""
    out = {}
    for seed in SEEDS:
        out[seed] = one(seed, True, True, tmp_path_factory.mktemp(f"seed{seed}"))
        print(f"seed {seed}: start / middle / end {out[seed]} dB")
    return out


def _like_the_middle(groups: Groups, judged: list[float]) -> None:
    """``judged`` within 0.3 dB of the middle targets' mean or better."""
    bar = float(np.mean(groups[1])) + 0.3
    for pslr in judged:
        assert pslr <= bar, groups


@pytest.mark.parametrize("seed", SEEDS)
def test_every_target_meets_the_bar(seed: int, runs: dict[int, Groups]) -> None:
    """Start, middle and end targets all at most -12.5 dB azimuth PSLR (seed 0's start
    targets too, whose comparison with the middle is the open xfail below)."""
    for pslr in [p for group in runs[seed] for p in group]:
        assert pslr <= -12.5, runs[seed]


@pytest.mark.parametrize("seed", SEEDS)
def test_end_targets_focus_like_the_middle(seed: int, runs: dict[int, Groups]) -> None:
    """Item 8: the targets whose aperture ends one subaperture before the run's end."""
    _like_the_middle(runs[seed], runs[seed][2])


@pytest.mark.parametrize(
    "seed",
    [
        pytest.param(
            0,
            marks=pytest.mark.xfail(
                strict=True,
                reason="open: seed 0's start targets are 0.35-0.5 dB under the middle "
                "(-12.66..-12.80 against -13.13 dB mean) with whole apertures; the former "
                "0.25-cell envelope threshold hid it",
            ),
        ),
        1,
        2,
    ],
)
def test_start_targets_focus_like_the_middle(seed: int, runs: dict[int, Groups]) -> None:
    """The targets lit from the run's first pulse."""
    _like_the_middle(runs[seed], runs[seed][0])
