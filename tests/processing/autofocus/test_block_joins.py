"""A block the never-worse guard leaves uncorrected joins its neighbours without a phase jump."""

from __future__ import annotations

import numpy as np

from sarmoco.processing.autofocus import (
    AutofocusGeometry,
    SlidingSubapertureAutofocus,
)
from sarmoco.processing.types import ComplexArray, FloatArray
from tests.processing.autofocus import _synth as S


class _RejectsOne(SlidingSubapertureAutofocus):
    """The real engine, with the guard's verdict on its second released block forced to
    'worse' (which blocks the guard refuses depends on the scene; the join must not)."""

    calls = 0

    def _no_worse(self, original: ComplexArray, focused: ComplexArray, t_s: FloatArray) -> bool:
        self.calls += 1
        return self.calls != 2 and super()._no_worse(original, focused, t_s)


def test_an_uncorrected_block_joins_its_neighbours_in_value_and_slope() -> None:
    """The absolute phase of the corrections carries an unobservable constant and slope
    (pinned over the first subaperture centres); a block left uncorrected and the next
    corrected one met with a jump of that phase, which defocused every target whose
    aperture spans the boundary (ku-vehicle x0.1 flight-log run: a 0.15-cycle jump 0.85 s
    before the end, the last targets -7.6..-8.0 dB azimuth PSLR; joined: -12.9). The
    uncorrected block's phase is the linear continuation of the block before it, and the
    next block continues it in value and slope."""
    dur = 4.0
    t = np.arange(round(dur * S.PRF_HZ)) / S.PRF_HZ - dur / 2
    d, a = S.sine_motion(t, (0.25, 0.1), (0.3, 0.45))
    xr = [(0, 1000), (4, 920), (-5, 1080), (8, 960), (-10, 1040), (10, 1050)]
    syn = S.make(dur, [S.ground_target(x, r) for x, r in xr], d, a, snr_db=10.0)
    geo = AutofocusGeometry(S.WAVELENGTH_M, S.SPEED_MPS, S.DEPTH_M, 1000.0)
    af = _RejectsOne(geo, syn.range_m, S.af_config(pin_window_s=0.5))
    t_ns = np.round(syn.t_s * 1e9).astype(np.int64) + 10**18
    blocks = []
    for i in range(0, t_ns.size, 50):
        corr = af.push(syn.rc[i : i + 50], t_ns[i : i + 50])[1]
        if corr.t_ns.size:
            blocks.append(((corr.t_ns - t_ns[0]) * 1e-9, corr.phase_cycles))
    last = af.flush()[1]
    blocks.append(((last.t_ns - t_ns[0]) * 1e-9, last.phase_cycles))
    blocks = [b for b in blocks if b[0].size]
    assert len(blocks) >= 4 and af.calls >= 3
    (t0, c0), (t1, c1), (t2, c2) = blocks[0], blocks[1], blocks[2]
    step = np.diff(t1)[:, None]
    # the uncorrected block: a straight line (an exactly linear phase does not focus)
    rates = np.diff(c1, axis=0) / step
    np.testing.assert_allclose(rates, np.broadcast_to(rates[0], rates.shape), rtol=0, atol=1e-6)
    for (ta, ca), (tb, cb) in (((t0, c0), (t1, c1)), ((t1, c1), (t2, c2))):
        slope_a = (ca[-1] - ca[-2]) / (ta[-1] - ta[-2])
        slope_b = (cb[1] - cb[0]) / (tb[1] - tb[0])
        jump = cb[0] - (ca[-1] + slope_a * (tb[0] - ta[-1]))
        print("jump (cycles)", jump, "slope change (Hz)", slope_b - slope_a)
        assert np.all(np.abs(jump) < 1e-6) and np.all(np.abs(slope_b - slope_a) < 1e-6)
    # the corrections do move the phase (the joins are not trivially continuous)
    assert np.ptp(np.concatenate([c0[:, 0], c2[:, 0]])) > 0.05
