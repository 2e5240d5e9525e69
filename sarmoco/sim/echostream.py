"""A run's raw echoes, whole or synthesized a block of pulses at a time as they are sent.

:func:`scene_echo` is the echo of a scenario's targets and clutter at some pulses
(:func:`sarmoco.sim.echo.synthesize` plus :func:`sarmoco.sim.extended.clutter_echo`).
A short run keeps every pulse's echo in one array; a long one (a 30-minute soak at
175 Hz is 315 000 pulses of 684 samples, 1.7 GB) is an :class:`EchoStream`: pulse ``k``
is synthesized with its block of :data:`BLOCK_PULSES` when the radar emitter first asks
for it, so the simulator starts at once and holds one block in memory.

Each block draws its noise from its own seed (the run's noise seed spawned with the
block's index): a block is the same whenever it is made, but the noise differs from the
one-array run of the same seed (the same statistics, other draws).
"""

from __future__ import annotations

import math

import numpy as np

from sarmoco.processing.types import ComplexArray, FloatArray, IntArray
from sarmoco.sim.echo import noise_sigma, synthesize
from sarmoco.sim.extended import clutter_echo
from sarmoco.sim.scenario import Scenario

ECHO_ARRAY_MAX_BYTES = 256 * 2**20
"""Runs whose echo array would be larger than this are streamed (:func:`streams`), bytes."""
BLOCK_PULSES = 256
"""Pulses synthesized at once by :class:`EchoStream`."""
NOISE_PEAK_SIGMAS = 7.0
"""Noise bound of :meth:`EchoStream.peak_iq_bound`, in standard deviations of I or Q (a
sample beyond it has probability 2.6e-12: about one in a 30-minute ku-vehicle soak's
4.3e8 values per thousand runs)."""


def scene_echo(
    scn: Scenario, t_ns: IntArray, apc_ned: FloatArray, rng: np.random.Generator
) -> ComplexArray:
    """Raw echoes of the scenario's targets and clutter at the given pulses.

    Parameters
    ----------
    scn : Scenario
        Radar, targets, clutter, SNR and beam.
    t_ns : ndarray of int64, shape (P,)
        Pulse transmit times, GPS ns.
    apc_ned : ndarray of float64, shape (P, 3)
        True APC at each pulse, NED, m.
    rng : numpy.random.Generator
        Thermal noise source.

    Returns
    -------
    ndarray of complex64, shape (P, scn.radar.n_samples)
    """
    targets, amps = scn.targets_array()
    echo = synthesize(
        scn.radar,
        t_ns,
        apc_ned,
        targets,
        amps,
        scn.snr_db,
        rng,
        illumination=scn.illumination(apc_ned, targets),
    )
    if scn.clutter is not None:
        half_beam = scn.integration_angle_rad / 2.0 if scn.mode == "stripmap" else None
        echo += clutter_echo(scn.radar, apc_ned, scn.clutter, scn.beam_axis_ned, half_beam)
    return echo


def streams(scn: Scenario, n_pulses: int) -> bool:
    """Whether ``n_pulses`` of ``scn`` are to be an :class:`EchoStream` (their array would
    exceed :data:`ECHO_ARRAY_MAX_BYTES`)."""
    return n_pulses * scn.radar.n_samples * np.dtype(np.complex64).itemsize > ECHO_ARRAY_MAX_BYTES


class EchoStream:
    """Echo rows of a run, synthesized by blocks of pulses when first asked for.

    Indexing with a pulse number gives that pulse's row (complex64, shape (S,)); rows are
    meant to be read in order (one block is kept).

    Parameters
    ----------
    scn : Scenario
    t_ns : ndarray of int64, shape (P,)
        Pulse transmit times, GPS ns.
    apc_ned : ndarray of float64, shape (P, 3)
        True APC at each pulse, NED, m.
    seed : numpy.random.SeedSequence
        Noise seed of the run; block ``b`` draws from it spawned with key ``b``.
    block_pulses : int
        Pulses per block.
    """

    def __init__(
        self,
        scn: Scenario,
        t_ns: IntArray,
        apc_ned: FloatArray,
        seed: np.random.SeedSequence,
        block_pulses: int = BLOCK_PULSES,
    ) -> None:
        self.scenario = scn
        self.t_ns = t_ns
        self.apc_ned = apc_ned
        self.seed = seed
        self.block_pulses = block_pulses
        self.shape = (int(t_ns.size), scn.radar.n_samples)
        self._index = -1
        self._rows: ComplexArray = np.zeros((0, self.shape[1]), dtype=np.complex64)

    def block(self, b: int) -> ComplexArray:
        """Echo of block ``b`` (pulses ``b * block_pulses`` up to the next block), (n, S)."""
        seed = np.random.SeedSequence(self.seed.entropy, spawn_key=(*self.seed.spawn_key, b))
        span = slice(b * self.block_pulses, (b + 1) * self.block_pulses)
        return scene_echo(
            self.scenario, self.t_ns[span], self.apc_ned[span], np.random.default_rng(seed)
        )

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, k: int) -> ComplexArray:
        if not 0 <= k < self.shape[0]:
            raise IndexError(f"echo stream: pulse {k} is not in 0..{self.shape[0] - 1}")
        b = k // self.block_pulses
        if b != self._index:
            self._rows, self._index = self.block(b), b
        return self._rows[k - b * self.block_pulses]

    def peak_iq_bound(self) -> float:
        """An upper bound of the run's largest |I| or |Q| (what a stream can give without
        making every echo).

        The targets' part at a pulse is at most the sum of their illuminated amplitudes;
        the clutter's at most the sum of all its amplitudes (loose: random phases add to
        far less); the noise's :data:`NOISE_PEAK_SIGMAS` standard deviations of I or Q.
        """
        scn = self.scenario
        targets, amps = scn.targets_array()
        peak = 0.0
        for i in range(0, self.shape[0], 16 * self.block_pulses):
            lit = scn.illumination(self.apc_ned[i : i + 16 * self.block_pulses], targets)
            peak = max(peak, float((lit @ np.abs(amps)).max(initial=0.0)))
        if scn.clutter is not None:
            peak += float(np.abs(scn.clutter.amplitude).sum())
        if scn.snr_db is not None:
            peak += NOISE_PEAK_SIGMAS * noise_sigma(scn.snr_db) / math.sqrt(2.0)
        return peak
