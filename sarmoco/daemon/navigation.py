"""Navigation of the pulses: the buffer and aligner that join them, and what fills a gap.

:func:`nav_alignment` builds a run's :class:`~sarmoco.daemon.navbuffer.NavBuffer` and the
:class:`~sarmoco.daemon.aligner.Aligner` that joins its navigation to the recorded pulses
(the single-channel and the array pipeline alike). :class:`NavPulses` are aligned pulses
with their navigation, as focusing gathers them. :class:`GapFill` gives the pulses a gap
left without navigation a place in the aperture: zero echoes and placeholder motion, so
that focusing sees a uniformly sampled aperture with a hole rather than a silent jump.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
import numpy.typing as npt

from sarmoco.daemon.aligner import AlignedBlock, Aligner, PulseQueue
from sarmoco.daemon.backlog import RecordedBatch
from sarmoco.daemon.config import Config
from sarmoco.daemon.navbuffer import NavBuffer
from sarmoco.processing.types import BoolArray, ComplexArray, FloatArray, IntArray
from sarmoco.store.flags import UNFOCUSABLE


def nav_alignment(cfg: Config, ring: PulseQueue, max_block: int) -> tuple[NavBuffer, Aligner]:
    """A run's navigation buffer and the aligner that joins it to the pulses of ``ring``,
    both configured from ``ins.*`` (clock-step tolerance, gap, bridged silence, latency
    budget, lever arm), releasing at most ``max_block`` pulses at a time. One place for
    both the single-channel and the array pipeline."""
    nav = NavBuffer(clock_tolerance_ns=round(cfg.ins.clock_step_tolerance_s * 1e9))
    aligner = Aligner(
        ring,
        nav,
        max_gap_ns=round(cfg.ins.max_gap_s * 1e9),
        latency_budget_ns=round(cfg.ins.latency_budget_s * 1e9),
        lever_arm_body_m=cfg.ins.lever_arm_m,
        max_block=max_block,
        bridge_gap_ns=round(cfg.ins.bridge_gap_s * 1e9),
    )
    return nav, aligner


def recorded(block: AlignedBlock) -> RecordedBatch:
    """The recorded pulses of a block the aligner took from the focus backlog."""
    assert isinstance(block.echoes, RecordedBatch)
    return block.echoes


@dataclass(frozen=True)
class NavPulses:
    """Aligned pulses with their navigation (rows in time order).

    Attributes
    ----------
    t_ns, pulse_id : ndarray of int64, shape (P,)
        Transmit time (GPS ns) and running number.
    usable : ndarray of bool, shape (P,)
        The pulse is focused (no :data:`~sarmoco.store.flags.UNFOCUSABLE` flag: it has
        navigation and was taken under the configured radar parameters).
    flags : ndarray of uint32, shape (P,)
        :class:`~sarmoco.store.flags.PulseFlag` bits.
    raw : ndarray of complex64, shape (P, S)
        Raw echoes.
    pos_ned, vel_ned : ndarray, shape (P, 3)
        Antenna position (m, relative) and velocity (m/s) at the pulses, NED.
    quat : ndarray, shape (P, 4)
        Attitude at the pulses (body to NED, scalar first).
    row : ndarray of int64, shape (P,)
        Row of each pulse in the store's ``pulses`` table.
    """

    t_ns: IntArray
    pulse_id: IntArray
    usable: BoolArray
    flags: npt.NDArray[np.uint32]
    raw: ComplexArray
    pos_ned: FloatArray
    vel_ned: FloatArray
    quat: FloatArray
    row: IntArray

    @classmethod
    def of(cls, block: AlignedBlock) -> NavPulses:
        """The pulses of an aligned block of recorded pulses (copies: focusing never
        writes into what the recording path holds)."""
        e = recorded(block)
        raw = e.complex_samples()  # int16 I/Q: converted into a new array
        if np.may_share_memory(raw, e.samples):  # complex64 samples: the ring's own
            raw = raw.copy()
        return cls(
            t_ns=e.t_ns.copy(),
            pulse_id=e.pulse_id.copy(),
            usable=(e.flags & UNFOCUSABLE) == 0,
            flags=e.flags.copy(),
            raw=raw,
            pos_ned=block.nav.pos_ned.copy(),
            vel_ned=block.nav.vel_ned.copy(),
            quat=block.nav.quat.copy(),
            row=e.row.copy(),
        )

    @classmethod
    def cat(cls, parts: list[NavPulses]) -> NavPulses:
        """``parts`` one after the other (one part: itself)."""
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))

    def since(self, first: int) -> NavPulses:
        """The pulses from row ``first`` on."""
        return NavPulses(*(getattr(self, f.name)[first:] for f in fields(self)))

    def upto(self, stop: int) -> NavPulses:
        """The pulses before row ``stop``."""
        return NavPulses(*(getattr(self, f.name)[:stop] for f in fields(self)))

    def rows(self, keep: BoolArray) -> NavPulses:
        """The pulses where ``keep`` is True."""
        return NavPulses(*(getattr(self, f.name)[keep] for f in fields(self)))

    def __len__(self) -> int:
        return int(self.t_ns.size)


class GapFill:
    """Placeholder navigation for the pulses without it, from the last pulse that had it.

    Parameters
    ----------
    t_ns : int
        Time of the first pulse with navigation, GPS ns.
    vel_ned : ndarray, shape (3,)
        Its antenna velocity, NED, m/s.
    quat : ndarray, shape (4,)
        Its attitude (body to NED, scalar first).
    """

    def __init__(self, t_ns: int, vel_ned: FloatArray, quat: FloatArray) -> None:
        self._last: tuple[int, FloatArray, FloatArray] = (t_ns, vel_ned, quat)
        """Time (GPS ns), velocity and attitude of the last pulse with navigation."""

    def fill(self, p: NavPulses) -> NavPulses:
        """``p`` with the echoes of pulses without navigation zeroed and placeholder motion
        for them; remembers the last pulse of ``p`` with navigation.

        The pulses keep their place in time, so the autofocus and the image see a
        uniformly sampled aperture with a hole (zeros) rather than a silent jump. The
        placeholder velocity is the straight line between the usable neighbours (the
        last one of the previous block before the first): across the hole D_los
        integrates exactly as if the pulses had been left out, and the placeholder
        never reaches the image because those echoes are zero. The pulses stay
        flagged in the store.
        """
        if not p.usable.all():
            p = self._blank(p)
        if p.usable.any():
            k = int(np.flatnonzero(p.usable)[-1])
            self._last = (int(p.t_ns[k]), p.vel_ned[k], p.quat[k])
        return p

    def _blank(self, p: NavPulses) -> NavPulses:
        """Zero the unusable pulses of ``p`` and interpolate their motion (see :meth:`fill`)."""
        usable = p.usable
        raw = p.raw.copy()
        raw[~usable] = 0
        known_t = p.t_ns[usable].astype(np.float64)
        known_v, known_q = p.vel_ned[usable], p.quat[usable]
        last_t, last_v, last_q = self._last
        if known_t.size == 0 or p.t_ns[0] < known_t[0]:
            known_t = np.concatenate([[float(last_t)], known_t])
            known_v = np.concatenate([last_v[None, :], known_v])
            known_q = np.concatenate([last_q[None, :], known_q])
        tf = p.t_ns.astype(np.float64)
        vel = np.column_stack([np.interp(tf, known_t, known_v[:, k]) for k in range(3)])
        nearest = np.clip(np.searchsorted(known_t, tf), 0, known_t.size - 1)
        quat = np.where(usable[:, None], p.quat, known_q[nearest])
        return replace(p, raw=raw, vel_ned=vel, quat=quat)
