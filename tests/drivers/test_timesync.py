"""Clock models: LinearClockFit follows a reference step instead of raising."""

from __future__ import annotations

import pytest

from sarmoco.drivers.timesync import LinearClockFit

SKEW = 40e-6
STEP_NS = 250_000_000


def test_linear_fit_follows_a_reference_step() -> None:
    fit = LinearClockFit(window=16, outlier_ns=1_000_000)
    period = 10_000_000
    accepted = []
    for k in range(60):
        dev = 1_000_000_000 + k * period
        ref = 7 * 10**18 + round(dev * (1 + SKEW)) + (STEP_NS if k >= 30 else 0)
        accepted.append(fit.add(dev, ref))  # raised IndexError at the 8th outlier in a row
    assert accepted[:30] == [True] * 30
    assert accepted[30:38] == [False] * 8  # window // 2 consecutive outliers: restart
    assert all(accepted[38:])
    assert fit.rejected == 8
    dev = 1_000_000_000 + 59 * period
    assert fit.map(dev) == pytest.approx(7 * 10**18 + dev * (1 + SKEW) + STEP_NS, abs=2)
