"""Pulses without navigation keep their place in the aperture (:class:`GapFill`): zero
echoes, and placeholder motion along which the displacement integrates exactly as if the
pulses had been left out."""

from __future__ import annotations

import numpy as np
import pytest

from sarmoco.daemon.aligner import AlignedBlock
from sarmoco.daemon.backlog import RecordedBatch
from sarmoco.daemon.navigation import GapFill, NavPulses
from sarmoco.processing.navinterp import PulseNav

PRI_NS = 1_000_000


def _pulses(t_ns: np.ndarray, usable: np.ndarray, rng: np.random.Generator) -> NavPulses:
    """Pulses at ``t_ns`` with random echoes, a velocity that turns and a random attitude."""
    n = t_ns.size
    vel = np.column_stack([25.0 + 0.1 * np.sin(t_ns * 1e-8), np.cos(t_ns * 1e-8), 0.2 * np.ones(n)])
    quat = rng.standard_normal((n, 4))
    raw = (rng.standard_normal((n, 8)) + 1j * rng.standard_normal((n, 8))).astype(np.complex64)
    return NavPulses(
        t_ns=t_ns, pulse_id=np.arange(n), usable=usable, flags=np.zeros(n, np.uint32), raw=raw,
        pos_ned=np.zeros((n, 3)), vel_ned=vel, quat=quat, row=np.arange(n),
    )  # fmt: skip


def _displacement(t_ns: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """Trapezoid integral of ``vel`` over ``t_ns``, m (as D_los is integrated)."""
    dt = np.diff(t_ns) * 1e-9
    return np.sum(0.5 * (vel[1:] + vel[:-1]) * dt[:, None], axis=0)


def test_a_hole_is_zeros_on_the_straight_line_between_its_neighbours() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(64, dtype=np.int64) * PRI_NS
    usable = np.ones(64, bool)
    usable[20:35] = False
    p = _pulses(t, usable, rng)
    fill = GapFill(int(t[0]), p.vel_ned[0], p.quat[0])
    out = fill.fill(p)
    assert not np.any(out.raw[~usable]) and np.array_equal(out.raw[usable], p.raw[usable])
    assert np.array_equal(out.vel_ned[usable], p.vel_ned[usable])
    assert np.array_equal(out.quat[usable], p.quat[usable])
    np.testing.assert_allclose(
        _displacement(t, out.vel_ned), _displacement(t[usable], p.vel_ned[usable]), rtol=1e-12
    )
    assert np.array_equal(out.quat[~usable], np.repeat(p.quat[35:36], 15, axis=0))


def test_a_block_that_begins_in_a_hole_starts_from_the_last_pulse_with_navigation() -> None:
    """A hole that began in the block before: its placeholder in this block runs from the
    last usable pulse of that block (which the fill remembers) to the first usable one
    here; the block before, which could not see the end of the hole, held the last
    velocity."""
    rng = np.random.default_rng(1)
    t = np.arange(96, dtype=np.int64) * PRI_NS
    usable = np.ones(96, bool)
    usable[40:70] = False
    whole = _pulses(t, usable, rng)
    fill = GapFill(int(t[0]), whole.vel_ned[0], whole.quat[0])
    first, second = fill.fill(whole.upto(50)), fill.fill(whole.since(50))
    v39, v70 = whole.vel_ned[39], whole.vel_ned[70]
    np.testing.assert_array_equal(first.vel_ned[40:], np.repeat(v39[None], 10, axis=0))
    share = (t[50:70] - t[39]) / (t[70] - t[39])
    np.testing.assert_allclose(second.vel_ned[:20], v39 + share[:, None] * (v70 - v39), rtol=1e-12)
    assert not np.any(first.raw[40:]) and not np.any(second.raw[:20])


@pytest.mark.parametrize("dtype", [np.int16, np.complex64])
def test_focused_pulses_are_never_the_recorded_ones(dtype: type) -> None:
    # the focuser works on the raw echoes in place: they must be copies of what the
    # recording path holds, whichever format the ring keeps (int16 I/Q or complex64)
    n, s = 3, 5
    rng = np.random.default_rng(2)
    iq = rng.integers(-900, 900, (n, s, 2)).astype(np.int16)
    samples = iq if dtype == np.int16 else iq.astype(np.float32).view(np.complex64)[..., 0]
    t = np.arange(n) * PRI_NS
    echoes = RecordedBatch(samples, t, np.arange(n), np.zeros(n, np.int32),
                           np.zeros(n, np.uint32), np.arange(n))  # fmt: skip
    nav = PulseNav(t, np.zeros((n, 3)), np.ones((n, 3)), np.ones((n, 4)), np.ones(n, bool))
    p = NavPulses.of(AlignedBlock(echoes, nav))
    assert p.raw.dtype == np.complex64 and p.raw.shape == (n, s)
    assert np.array_equal(p.raw, iq[..., 0] + 1j * iq[..., 1])
    assert not np.may_share_memory(p.raw, samples)
