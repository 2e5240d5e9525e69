"""Release pulses with their navigation once the INS brackets them.

The aligner sits between the echo ring and the processor. A pulse leaves the
ring (in order) as soon as INS kinematics and attitude samples bracket it with
no more than ``bridge_gap_ns`` between them (with a lever arm, also once one more
attitude sample has arrived, so that the arm's rate is a central difference).

- Samples at most ``max_gap_ns`` apart (a few INS periods): ordinary interpolation.
- Further apart, up to ``bridge_gap_ns`` (a short INS silence): the navigation is
  interpolated across the silence all the same, from the samples on both sides
  (velocity by the cubic Hermite through both ends' velocities and accelerations,
  :func:`~sarmoco.processing.navinterp.bridge_gap`, the accelerations fitted over
  :data:`BRIDGE_FIT_NS` of samples beyond each end; attitude by SLERP: a vehicle's
  velocity does not jump within a fraction of a second, and the autofocus removes
  what the cubic misses), and the pulse is flagged
  :attr:`~sarmoco.store.flags.PulseFlag.NAV_BRIDGED`: it is focused, and the store
  says which pulses had bridged navigation. The pulses of the silence wait in the
  ring for :data:`BRIDGE_FIT_NS` of samples after it.

If no bracket within ``bridge_gap_ns`` exists ``latency_budget_ns`` after the
pulse time, the pulse leaves anyway, flagged:
:attr:`~sarmoco.store.flags.PulseFlag.NAV_GAP` when navigation exists after the
pulse but the samples around it are too far apart (a long dropout, refused samples),
:attr:`~sarmoco.store.flags.PulseFlag.NAV_TIMEOUT` when the INS has not
reached the pulse time yet. These pulses get NaN navigation and are not focused.
Waiting the whole budget before calling a gap a gap lets reordered samples fill
it; a silence longer than the budget cannot be bridged (its first pulses time out).

"Now" is whatever clock the caller runs on, in GPS ns: the host's GPS time
live, the virtual clock of a replay (e.g. the time of the newest item fed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from sarmoco.daemon.echoring import EchoBatch
from sarmoco.daemon.navbuffer import NO_TIME, NavBuffer, NavStream
from sarmoco.errors import ProcessingError
from sarmoco.processing.geometry import lever_arm_ned
from sarmoco.processing.navinterp import PulseNav, bridge_gap, interpolate_nav
from sarmoco.processing.types import BoolArray, FloatArray, IntArray, NavSamples
from sarmoco.store.flags import PulseFlag


class PulseQueue(Protocol):
    """Where the aligner takes pulses from, oldest first: an
    :class:`~sarmoco.daemon.echoring.EchoRing`, or the recorded pulses waiting to be
    focused (:class:`~sarmoco.daemon.backlog.FocusBacklog`). A :meth:`pop` takes the
    pulses the last look (``len``, :meth:`peek_times`) saw first."""

    def __len__(self) -> int:
        """Pulses ready to be taken."""

    def peek_times(self, max_n: int | None = None) -> IntArray:
        """Times of the oldest ready pulses, GPS ns."""

    def pop(self, n: int) -> EchoBatch:
        """Take the ``n`` oldest ready pulses out."""


@dataclass(frozen=True)
class AlignedBlock:
    """Pulses released together, oldest first.

    Attributes
    ----------
    echoes : EchoBatch
        Samples and metadata out of the ring; ``echoes.flags`` include the
        navigation flags set here.
    nav : PulseNav
        Navigation at each pulse time: position (NaN when the INS gives none),
        velocity and attitude of the antenna phase centre when a lever arm is
        configured, else of the IMU; NED, m, m/s. NaN and ``valid`` False where
        flagged.
    """

    echoes: EchoBatch
    nav: PulseNav

    def __len__(self) -> int:
        return len(self.echoes)


BRIDGE_FIT_NS = 100_000_000
"""Span of INS samples beyond each end of a bridged silence from which its end
accelerations are fitted, ns (0.1 s: 10-20 samples at 100-200 Hz, short against the
turbulence's periods)."""

_UNBRACKETED = np.iinfo(np.int64).max
"""Bracket span of a pulse without a sample on one side, ns."""


def _bracket_span(stream: NavStream, t_ns: IntArray) -> tuple[IntArray, BoolArray]:
    """Per pulse: time between the samples around it (ns, :data:`_UNBRACKETED` without a
    sample on both sides), and whether any sample at or after it exists."""
    before, after = stream.bracket(t_ns)
    has_after = after != NO_TIME
    both = (before != NO_TIME) & has_after
    span = np.full(t_ns.shape, _UNBRACKETED, dtype=np.int64)
    span[both] = after[both] - before[both]
    return span, has_after


class Aligner:
    """Takes pulses out of a :class:`PulseQueue` with navigation from a :class:`NavBuffer`.

    Parameters
    ----------
    ring : PulseQueue
        Where the pulses wait (the echo ring, or the recorded pulses waiting to be
        focused); ``echoes`` of the blocks released are what its ``pop`` gives.
    nav : NavBuffer
        Where the INS reader pushes samples.
    max_gap_ns : int
        Longest INS sample interval interpolated across without a flag, ns (a few INS
        periods).
    latency_budget_ns : int
        Longest a pulse waits for the INS, ns.
    max_block : int
        Most pulses released by one :meth:`poll` (the daemon's ``imaging.block_pulses``).
    bridge_gap_ns : int, optional
        Longest INS silence interpolated across, flagged ``NAV_BRIDGED``, ns (default, or
        anything up to ``max_gap_ns``: no bridging).
    lever_arm_body_m : tuple of 3 float, optional
        APC minus IMU in the body frame (x forward, y right, z down), m. With it,
        positions and velocities are of the antenna phase centre.

    Attributes
    ----------
    released, nav_gap, nav_timeout, nav_bridged : int
        Pulses released in all, and of them flagged for a gap, a timeout or bridged.
    """

    def __init__(
        self,
        ring: PulseQueue,
        nav: NavBuffer,
        max_gap_ns: int,
        latency_budget_ns: int,
        max_block: int,
        lever_arm_body_m: tuple[float, float, float] | None = None,
        bridge_gap_ns: int = 0,
    ) -> None:
        if max_gap_ns <= 0 or latency_budget_ns < 0 or max_block < 1:
            raise ProcessingError(
                f"Aligner: max_gap_ns {max_gap_ns} must be > 0, latency_budget_ns "
                f"{latency_budget_ns} >= 0, max_block {max_block} >= 1"
            )
        self.ring = ring
        self.nav = nav
        self.max_gap_ns = max_gap_ns
        self.bridge_gap_ns = max(max_gap_ns, bridge_gap_ns)
        self.latency_budget_ns = latency_budget_ns
        self.lever_arm_body_m = (
            None if lever_arm_body_m is None else np.asarray(lever_arm_body_m, dtype=np.float64)
        )
        self.max_block = max_block
        self.released = 0
        self.nav_gap = 0
        self.nav_timeout = 0
        self.nav_bridged = 0

    @property
    def reach_ns(self) -> int:
        """How far before a pulse the kinematics samples its navigation is made from may
        lie (the longest silence bridged and the span its end accelerations are fitted
        over), ns."""
        return self.bridge_gap_ns + BRIDGE_FIT_NS

    def poll(self, now_ns: int) -> AlignedBlock | None:
        """Release the oldest pulses that are bracketed or out of time, if any.

        Parameters
        ----------
        now_ns : int
            Current time, GPS ns (see the module doc).

        Returns
        -------
        AlignedBlock or None
            Up to ``max_block`` pulses, in order; None when the oldest pulse must wait.
        """
        t = self.ring.peek_times(self.max_block)
        if t.shape[0] == 0:
            return None
        span, settled = self._status(t)
        ok = span <= self.bridge_gap_ns
        ready = ok & self._lookahead(t) & self._fit_ready(t, span)
        decided = ready | (now_ns - t > self.latency_budget_ns)
        n = t.shape[0] if decided.all() else int(np.argmin(decided))
        if n == 0:
            return None
        return self._release(n, span[:n], settled[:n])

    def flush(self) -> AlignedBlock | None:
        """Release every pulse in the ring now (end of a run), flagging the uncovered ones."""
        n = len(self.ring)
        if n == 0:
            return None
        t = self.ring.peek_times(n)
        span, settled = self._status(t)
        return self._release(n, span, settled)

    def _status(self, t: IntArray) -> tuple[IntArray, BoolArray]:
        """Per pulse: the longer bracket span of the two streams (ns), and whether both
        streams hold a sample at or after it."""
        span_k, after_k = _bracket_span(self.nav.kinematics, t)
        span_a, after_a = _bracket_span(self.nav.attitude, t)
        return np.maximum(span_k, span_a), after_k & after_a

    def _fit_ready(self, t: IntArray, span: IntArray) -> BoolArray:
        """Pulses across a silence: :data:`BRIDGE_FIT_NS` of kinematics samples after it held."""
        _, after = self.nav.kinematics.bracket(t)
        newest = self.nav.kinematics.span_ns()
        if newest is None:
            return span <= self.max_gap_ns
        return (span <= self.max_gap_ns) | (after <= newest[1] - BRIDGE_FIT_NS)

    def _lookahead(self, t: IntArray) -> BoolArray:
        """With a lever arm: an attitude sample beyond the bracket exists (for the arm's rate)."""
        if self.lever_arm_body_m is None:
            return np.ones(t.shape[0], dtype=bool)
        _, after = self.nav.attitude.bracket(t)
        _, beyond = self.nav.attitude.bracket(np.where(after == NO_TIME, t, after + 1))
        return (after != NO_TIME) & (beyond != NO_TIME)

    def _release(self, n: int, span: IntArray, settled: BoolArray) -> AlignedBlock:
        echoes = self.ring.pop(n)
        nav = self._interpolate(echoes.t_ns, span <= self.bridge_gap_ns)
        gap = ~nav.valid & settled
        timeout = ~nav.valid & ~settled
        bridged = nav.valid & (span > self.max_gap_ns)
        echoes.flags[gap] |= np.uint32(PulseFlag.NAV_GAP)
        echoes.flags[timeout] |= np.uint32(PulseFlag.NAV_TIMEOUT)
        echoes.flags[bridged] |= np.uint32(PulseFlag.NAV_BRIDGED)
        self.released += n
        self.nav_gap += int(gap.sum())
        self.nav_timeout += int(timeout.sum())
        self.nav_bridged += int(bridged.sum())
        return AlignedBlock(echoes, nav)

    def _interpolate(self, t: IntArray, ok: BoolArray) -> PulseNav:
        """Navigation at the pulse times; NaN and invalid where ``ok`` is False."""
        p = t.shape[0]
        pos, vel, quat = np.full((p, 3), np.nan), np.full((p, 3), np.nan), np.full((p, 4), np.nan)
        valid = ok.copy()
        if ok.any():
            tq = t[ok]
            reach = self.reach_ns
            tk, vk = self.nav.kinematics.window(int(tq.min()) - reach, int(tq.max()) + reach)
            ta, qa = self.nav.attitude.window(int(tq.min()), int(tq.max()), extra=2)
            has_pos = not np.isnan(vk[:, 3:]).any()
            identity = np.tile([1.0, 0.0, 0.0, 0.0], (tk.shape[0], 1))
            kin_nav = NavSamples(tk, vk[:, :3], identity, vk[:, 3:] if has_pos else None)
            att_nav = self._lever_track(ta, qa)
            # the INS's own velocity, not its positions' derivative (navinterp: velocity)
            kin_q = interpolate_nav(
                kin_nav, tq, self.bridge_gap_ns, strict=False, velocity="samples"
            )
            kin = self._bridge(kin_nav, tq, kin_q)
            att = interpolate_nav(att_nav, tq, self.bridge_gap_ns, strict=False)
            pos_q, vel_q = kin.pos_ned, kin.vel_ned
            if self.lever_arm_body_m is not None:
                pos_q = pos_q + att.pos_ned
                vel_q = vel_q + att.vel_ned
            pos[ok] = pos_q if has_pos else np.nan
            vel[ok] = vel_q
            quat[ok] = att.quat
            valid[ok] = kin.valid & att.valid
        pos[~valid] = vel[~valid] = quat[~valid] = np.nan
        return PulseNav(t_ns=t, pos_ned=pos, vel_ned=vel, quat=quat, valid=valid)

    def _bridge(self, nav: NavSamples, t: IntArray, kin: PulseNav) -> PulseNav:
        """``kin`` with the velocity (and position) of the pulses inside silences longer
        than ``max_gap_ns`` from :func:`~sarmoco.processing.navinterp.bridge_gap`."""
        if nav.t_ns.shape[0] < 2:
            return kin
        i = np.searchsorted(nav.t_ns, t, side="right") - 1
        inside = (i >= 0) & (i < nav.t_ns.shape[0] - 1) & kin.valid
        i_c = np.clip(i, 0, nav.t_ns.shape[0] - 2)
        long = inside & (nav.t_ns[i_c + 1] - nav.t_ns[i_c] > self.max_gap_ns)
        for gap in np.unique(i[long]).tolist():
            rows = long & (i == gap)
            vel, pos = bridge_gap(nav, gap, t[rows], BRIDGE_FIT_NS)
            kin.vel_ned[rows] = vel
            if pos is not None:
                kin.pos_ned[rows] = pos
        return kin

    def _lever_track(self, ta: IntArray, qa: FloatArray) -> NavSamples:
        """Attitude samples carrying the rotated lever arm as a position track.

        Position: ``R(q) l`` at each attitude sample, NED m (zero without a lever
        arm); velocity: its rate from the chords to both neighbours (the
        non-uniform three-point derivative; one-sided at the ends and next to a
        gap), so that :func:`interpolate_nav` gives the lever arm and its rate at
        the pulses by the same Hermite cubic as the IMU track.
        """
        n = ta.shape[0]
        if self.lever_arm_body_m is None or n < 2:
            return NavSamples(ta, np.zeros((n, 3)), qa, np.zeros((n, 3)))
        arm = lever_arm_ned(qa, self.lever_arm_body_m)
        h = (np.diff(ta) * 1e-9)[:, None]
        chord = np.diff(arm, axis=0) / h
        rate = np.empty_like(arm)
        rate[0], rate[-1] = chord[0], chord[-1]
        h1, h2, c1, c2 = h[:-1], h[1:], chord[:-1], chord[1:]
        rate[1:-1] = (h1 * c2 + h2 * c1) / (h1 + h2)
        gap = self.max_gap_ns * 1e-9
        rate[1:-1] = np.where(h1 > gap, c2, np.where(h2 > gap, c1, rate[1:-1]))
        return NavSamples(ta, rate, qa, arm)
