"""Clock models: LinearClockFit follows a reference step instead of raising."""

from __future__ import annotations

import pytest

from sarmoco.drivers.timesync import MAX_SKEW, LinearClockFit

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


def test_linear_fit_does_not_believe_a_skew_beyond_a_crystal() -> None:
    """Four pairs over 1.5 s with ±1 ms of jitter (a loaded host answering TIMESYNC late)
    fit a skew of -1300 ppm; the fit clips it to MAX_SKEW, and the mapping error one second past
    the last pair stays within the jitter plus MAX_SKEW × 2.5 s (unclipped: 2.3 ms)."""
    fit = LinearClockFit(min_pairs=3)
    ms = 1_000_000
    t0 = 10**18
    jitter = [+1 * ms, +0.3 * ms, -0.3 * ms, -1 * ms]  # true skew 0: pure jitter
    for k, j in enumerate(jitter):
        dev = k * 500 * ms
        fit.add(dev, t0 + dev + round(j))
    dev = 2500 * ms
    err = fit.map(dev) - (t0 + dev)
    assert abs(err) <= 1 * ms + MAX_SKEW * 1e9 * 2.5
    unclipped = LinearClockFit(min_pairs=3, max_skew=1.0)
    for k, j in enumerate(jitter):
        unclipped.add(k * 500 * ms, t0 + k * 500 * ms + round(j))
    assert abs(unclipped.map(dev) - (t0 + dev)) > 2 * ms  # what the clip prevents
