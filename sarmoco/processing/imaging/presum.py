"""Streaming azimuth pre-filter: low-pass and decimate range-compressed pulses in slow time.

Backprojection costs per pulse, while a pixel only takes the pulses that see it
within the (culled) beam, so the slow-time signal a pixel integrates has Doppler
``|f| <= f_b = 2 v sin(theta / 2) / lambda``. The PRF is often many times that
band (thz-spotlight: 20 kHz against f_b of about 0.2 kHz). Each range bin is
filtered along slow time by a linear-phase FIR low-pass whose passband holds
``f_b`` and every ``D``-th output is kept (presumming with a proper filter):

- ``D`` is the largest integer with ``PRF / D >= oversampling * 2 f_b``;
- passband ``|f| <= f_b``, stopband from ``PRF / D - f_b`` (what folds onto the
  passband after decimation), Kaiser window design to ``ATTENUATION_DB``;
- an odd number of taps, so output ``m`` is centred on an input pulse slot
  (its time is that slot's time) and the filter delays nothing; DC gain ``D``,
  so the backprojected sum over the decimated pulses keeps the image's scale.

A squinted beam (an antenna fixed to a crabbed body) moves the band to
``f_dc ± f_b`` about its Doppler centroid ``f_dc`` (:attr:`AzimuthPrefilter.centroid_hz`,
set per block from the attitude; it may lie beyond ``PRF / 2``, the band is the
same). Each slot is demodulated by ``exp(-j phi(t))`` before the low-pass and each
output remodulated by ``exp(+j phi(t))`` at its centre slot, ``phi`` the running
integral of ``2 pi f_dc`` over the slot times (continuous where the centroid
changes): the filter is then a band-pass about the centroid, and an output is the
band-limited signal at its slot, as backprojection needs it.

The filter runs on a uniform grid of pulse slots at the nominal PRF: a pulse
``round(dt * PRF)`` slots after the previous one leaves empty slots as zeros
(dropped pulses); a gap longer than the filter ends the run (as :meth:`flush`)
and the next pulse starts a new one. Before the first and after the last
pulse of a run the slots are zeros, and the outputs whose filter window reaches
any pulse are all produced, so the aperture's edges are treated alike.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import ComplexArray, IntArray

PREFILTER_OVERSAMPLING = 1.25
"""Default pulse rate after the pre-filter over the two-sided Doppler band it keeps."""

ATTENUATION_DB = 60.0
"""Stopband attenuation of the Kaiser design, dB (passband deviation of the same order, < 0.3 %)."""

_CHUNK = 512
"""Float32 columns per parallel work item of the FIR kernel."""


@numba.njit(parallel=True, nogil=True, cache=True, fastmath=True)
def _fir_decimate(
    hist: npt.NDArray[np.float32],
    new: npt.NDArray[np.float32],
    taps: npt.NDArray[np.float32],
    first: int,
    step: int,
    out: npt.NDArray[np.float32],
) -> None:  # pragma: no cover - compiled
    """``out[m] = sum_k taps[k] x[first + m step + k]``, ``x`` the rows of ``hist`` then ``new``.

    Symmetric taps, so this is the convolution. Each input row is read once per
    column chunk and added to the (few) outputs whose window holds it, which stay
    in cache; chunks of columns run in parallel.
    """
    n_out, width = out.shape
    n_taps = taps.shape[0]
    n_hist = hist.shape[0]
    n_chunks = (width + _CHUNK - 1) // _CHUNK
    last_row = first + (n_out - 1) * step + n_taps
    for c in numba.prange(n_chunks):
        b0 = c * _CHUNK
        nb = min(b0 + _CHUNK, width) - b0
        acc = np.zeros((n_out, _CHUNK), np.float32)
        row = np.empty(_CHUNK, np.float32)  # a local copy: the loop below then vectorises
        for r in range(first, last_row):
            if r < n_hist:
                for b in range(nb):
                    row[b] = hist[r, b0 + b]
            else:
                for b in range(nb):
                    row[b] = new[r - n_hist, b0 + b]
            m_lo = max(0, (r - first - n_taps + step) // step)
            m_hi = min(n_out - 1, (r - first) // step)
            for m in range(m_lo, m_hi + 1):
                h = taps[r - first - m * step]
                a = acc[m]
                for b in range(_CHUNK):
                    a[b] += h * row[b]
        for m in range(n_out):
            for b in range(nb):
                out[m, b0 + b] = acc[m, b]


def kaiser_lowpass(
    rate_hz: float, pass_hz: float, stop_hz: float, attenuation_db: float
) -> npt.NDArray[np.float64]:
    """Taps of a linear-phase FIR low-pass by the Kaiser window method, odd in number.

    Kaiser's estimates (J. F. Kaiser, "Nonrecursive digital filter design using the
    I0-sinh window function", 1974) give the window's shape ``beta`` and the length for
    ``attenuation_db`` over the transition band ``[pass_hz, stop_hz]``; the length is made
    odd, and the ideal low-pass cut at the middle of the transition band is windowed:
    the taps of ``scipy.signal.firwin(n, cutoff, window=("kaiser", beta), fs=rate_hz)``
    with ``n, beta`` from ``scipy.signal.kaiserord``, without importing ``scipy.signal``:
    that import is the largest part of a daemon process's start.

    Parameters
    ----------
    rate_hz : float
        Sample rate, Hz.
    pass_hz, stop_hz : float
        Passband and stopband edges, Hz, ``0 < pass_hz < stop_hz <= rate_hz / 2``.
    attenuation_db : float
        Stopband attenuation, dB (>= 8).

    Returns
    -------
    ndarray of float64, shape (2 M + 1,)
        Symmetric taps, DC gain 1.

    Raises
    ------
    ProcessingError
        An attenuation below 8 dB.
    """
    a = float(attenuation_db)
    if a < 8.0:
        raise ProcessingError(f"kaiser_lowpass: attenuation {a!r} dB below the design's 8 dB")
    beta = 0.1102 * (a - 8.7) if a > 50.0 else 0.0
    if 21.0 < a <= 50.0:
        beta = 0.5842 * (a - 21.0) ** 0.4 + 0.07886 * (a - 21.0)
    width = (stop_hz - pass_hz) / (rate_hz / 2.0)
    n_taps = math.ceil((a - 7.95) / 2.285 / (math.pi * width) + 1.0)
    n_taps += 1 - n_taps % 2
    cutoff = (pass_hz + stop_hz) / rate_hz  # of the Nyquist frequency
    m = np.arange(n_taps) - (n_taps - 1) / 2.0
    taps = cutoff * np.sinc(cutoff * m) * np.kaiser(n_taps, beta)
    return taps / taps.sum()


class AzimuthPrefilter:
    """Low-pass filter and decimate pulses along slow time, streaming (see the module).

    Parameters
    ----------
    prf_hz : float
        Nominal pulse repetition frequency of the input, Hz.
    band_hz : float
        One-sided Doppler band to keep, ``f_b``, Hz.
    oversampling : float
        Output pulse rate over the two-sided band ``2 f_b`` (> 1).
    attenuation_db : float
        Stopband attenuation of the design, dB.

    Attributes
    ----------
    centroid_hz : float
        Doppler centroid ``f_dc`` the band is centred on, Hz (0: broadside); applies to
        the pulses pushed after it is set.
    """

    def __init__(
        self,
        prf_hz: float,
        band_hz: float,
        oversampling: float = PREFILTER_OVERSAMPLING,
        attenuation_db: float = ATTENUATION_DB,
    ) -> None:
        if not (prf_hz > 0 and band_hz > 0 and oversampling > 1 and attenuation_db > 0):
            raise ProcessingError(
                f"AzimuthPrefilter: PRF {prf_hz!r} Hz, band {band_hz!r} Hz, oversampling "
                f"{oversampling!r}, attenuation {attenuation_db!r} dB must all be > 0 (> 1)"
            )
        self.prf_hz = float(prf_hz)
        self.band_hz = float(band_hz)
        self.decimation = max(1, math.floor(prf_hz / (2.0 * band_hz * oversampling)))
        """Input pulse slots per output pulse, D."""
        taps = np.ones(1)
        if self.decimation > 1:
            stop_hz = prf_hz / self.decimation - band_hz
            taps = kaiser_lowpass(prf_hz, band_hz, stop_hz, attenuation_db)
            taps *= self.decimation / taps.sum()
        self.taps = taps.astype(np.float32)
        """FIR taps, odd length 2 M + 1, symmetric, sum D."""
        self._half = (self.taps.size - 1) // 2
        self._period_ns = 1e9 / prf_hz
        self._hist: ComplexArray | None = None
        """The 2 M slots before the next one (samples)."""
        self._hist_t = np.zeros(0, np.int64)
        """GPS times of those slots, ns."""
        self._next_slot = 0
        """Slot index of the next input pulse (0 = the first pulse of the run)."""
        self._next_out = 0
        """Centre slot of the next output (a multiple of D)."""
        self._last_t = 0
        """Time of the last input pulse, GPS ns."""
        self.centroid_hz = 0.0
        self._hist_phi = np.zeros(0)
        """Demodulation phase phi of the history slots, rad."""
        self._last_phi = 0.0
        """phi at the last input pulse's time, rad."""
        self._centroid_from_ns = np.zeros(0, np.int64)
        self._centroids_hz = np.zeros(0)
        """Slot times (GPS ns) from which each centroid the slots were demodulated by held."""

    def passband_hz(self, t_ns: IntArray) -> npt.NDArray[np.float64]:
        """Doppler band the outputs centred at ``t_ns`` (GPS ns, increasing across calls)
        hold, Hz, (P, 2): ``centroid ± band_hz`` with the centroid their centre slot was
        demodulated by. The centroids before the one of the first of them are forgotten.

        An output holds that band and, at the output rate, the aliases of what lies
        beside it: whoever integrates an output over more Doppler than the band takes
        those aliases for signal.
        """
        t_ns = np.asarray(t_ns, dtype=np.int64)
        if self._centroids_hz.size == 0:
            centroid = np.full(t_ns.shape, self.centroid_hz)
        else:
            k = np.clip(np.searchsorted(self._centroid_from_ns, t_ns, side="right") - 1, 0, None)
            first = int(k[0]) if k.size else 0
            self._centroid_from_ns = self._centroid_from_ns[first:]
            self._centroids_hz = self._centroids_hz[first:]
            centroid = self._centroids_hz[k - first]
        return np.column_stack([centroid - self.band_hz, centroid + self.band_hz])

    @property
    def delay_slots(self) -> int:
        """Slots an output waits for after its centre slot (half the filter length), M."""
        return self._half

    def push(self, rc: ComplexArray, t_ns: IntArray) -> tuple[ComplexArray, IntArray]:
        """Filter a block of pulses; return the outputs that are complete.

        Parameters
        ----------
        rc : ndarray of complex, shape (P, S)
            Range-compressed pulses (any complex dtype; computed in complex64).
        t_ns : ndarray of int64, shape (P,)
            Pulse times, GPS ns, increasing across calls.

        Returns
        -------
        out : ndarray of complex64, shape (Q, S)
            Filtered, decimated pulses (``rc`` itself when D = 1).
        t_out : ndarray of int64, shape (Q,)
            Time of each output's centre slot, GPS ns.
        """
        t_ns = np.asarray(t_ns, dtype=np.int64)
        if rc.ndim != 2 or t_ns.shape != (rc.shape[0],):
            raise ProcessingError(f"AzimuthPrefilter: rc{rc.shape} and t_ns{t_ns.shape}")
        if self.decimation == 1 or rc.shape[0] == 0:
            return rc, t_ns
        if self._hist is None:
            self._start(rc.shape[1], int(t_ns[0]))
        steps = slot_steps(t_ns, self._last_t, self._period_ns)
        if np.any(steps < 1):
            raise ProcessingError("AzimuthPrefilter: pulse times do not increase by a slot")
        gap = np.flatnonzero(steps > self.taps.size)
        if gap.size:  # a gap the filter does not bridge: end the run there, start a new one
            g = int(gap[0])
            head = self._run(rc[:g], t_ns[:g], steps[:g]) if g else _empty(rc.shape[1])
            return _concat([head, self.flush(), self.push(rc[g:], t_ns[g:])], rc.shape[1])
        return self._run(rc, t_ns, steps)

    def flush(self) -> tuple[ComplexArray, IntArray]:
        """End the run: the outputs whose window still reaches a pulse (zeros after it)."""
        if self._hist is None:
            return _empty(0)
        n_pad = 2 * self._half
        pad = np.zeros((n_pad, self._hist.shape[1]), np.complex64)
        t_pad = self._last_t + np.rint(np.arange(1, n_pad + 1) * self._period_ns).astype(np.int64)
        out = self._filter(pad, t_pad, self._phases(t_pad), self._next_slot - 1 + self._half)
        self._hist = None
        return out

    def _start(self, n_samples: int, t0_ns: int) -> None:
        n = self.taps.size - 1
        self._hist = np.zeros((n, n_samples), np.complex64)
        self._hist_t = t0_ns + np.rint(np.arange(-n, 0) * self._period_ns).astype(np.int64)
        self._next_slot = 0
        d = self.decimation
        self._next_out = -(self._half // d) * d  # first centre whose window reaches slot 0
        self._last_t = t0_ns - round(self._period_ns)
        self._last_phi = 0.0
        dt = (self._hist_t - self._last_t).astype(np.float64)
        self._hist_phi = np.asarray(2e-9 * math.pi * self.centroid_hz * dt, dtype=np.float64)

    def _run(
        self, rc: ComplexArray, t_ns: IntArray, steps: IntArray
    ) -> tuple[ComplexArray, IntArray]:
        """Place a block without long gaps on its slots (zeros between) and filter."""
        new, t_new = fill_slots(rc, t_ns, steps, self._last_t)
        if self._centroids_hz.size == 0 or self._centroids_hz[-1] != self.centroid_hz:
            self._centroid_from_ns = np.append(self._centroid_from_ns, t_new[0])
            self._centroids_hz = np.append(self._centroids_hz, self.centroid_hz)
        phi = self._phases(t_new)
        if self.centroid_hz != 0.0 or np.any(phi != 0.0):
            new = new * np.exp(-1j * phi).astype(np.complex64)[:, None]
        self._last_t = int(t_ns[-1])
        return self._filter(new, t_new, phi, self._next_slot + new.shape[0] - 1 - self._half)

    def _phases(self, t_ns: IntArray) -> npt.NDArray[np.float64]:
        """Demodulation phase phi at the slot times ``t_ns`` following the last input, rad
        (advances :attr:`_last_phi` to the last of them)."""
        dt = np.diff(np.asarray(t_ns, dtype=np.int64), prepend=self._last_t).astype(np.float64)
        phi = self._last_phi + 2e-9 * math.pi * self.centroid_hz * np.cumsum(dt)
        if phi.size:
            self._last_phi = float(phi[-1])
        return phi

    def _filter(
        self,
        new: ComplexArray,
        t_new: IntArray,
        phi_new: npt.NDArray[np.float64],
        last_centre: int,
    ) -> tuple[ComplexArray, IntArray]:
        """Append the slots ``new`` (demodulated by ``phi_new``, rad); produce the outputs
        centred up to ``last_centre``, remodulated."""
        hist = self._hist
        assert hist is not None
        t_x = np.concatenate([self._hist_t, t_new])
        phi_x = np.concatenate([self._hist_phi, phi_new])
        first_slot = self._next_slot - hist.shape[0]  # slot of the first history row
        d = self.decimation
        n_out = max(0, (last_centre - self._next_out) // d + 1)
        out = np.empty((n_out, hist.shape[1]), np.complex64)
        centres = self._next_out + d * np.arange(n_out)
        if n_out:
            first_row = self._next_out - self._half - first_slot
            _fir_decimate(
                hist.view(np.float32), new.view(np.float32), self.taps, first_row, d,
                out.view(np.float32),
            )  # fmt: skip
        self._next_out += d * n_out
        self._next_slot += new.shape[0]
        n_hist = hist.shape[0]
        if new.shape[0] >= n_hist:
            self._hist = new[new.shape[0] - n_hist :].copy()
        else:
            self._hist = np.concatenate([hist[new.shape[0] :], new])
        self._hist_t = t_x[t_x.shape[0] - n_hist :].copy()
        self._hist_phi = phi_x[phi_x.shape[0] - n_hist :].copy()
        phi_out = phi_x[centres - first_slot]
        if np.any(phi_out != 0.0):
            out *= np.exp(1j * phi_out).astype(np.complex64)[:, None]
        return out, t_x[centres - first_slot]


def slot_steps(t_ns: IntArray, last_ns: int, period_ns: float) -> IntArray:
    """Slots of the nominal PRF grid from each pulse's predecessor to it.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    last_ns : int
        Time of the pulse before the first, GPS ns.
    period_ns : float
        Nominal pulse repetition interval, ns.

    Returns
    -------
    ndarray of int64, shape (P,)
        ``round((t_k - t_{k-1}) / period)``: 1 between consecutive pulses, ``1 + m``
        after ``m`` missing ones.
    """
    return np.rint(np.diff(t_ns, prepend=last_ns) / period_ns).astype(np.int64)


def fill_slots(
    rc: ComplexArray, t_ns: IntArray, steps: IntArray, last_ns: int
) -> tuple[ComplexArray, IntArray]:
    """Pulses on their slots of the PRF grid: a zero row in every empty slot.

    Parameters
    ----------
    rc : ndarray of complex, shape (P, S)
        Pulses (range-compressed or raw).
    t_ns : ndarray of int64, shape (P,)
        Their times, GPS ns, increasing.
    steps : ndarray of int, shape (P,)
        Slots from each pulse's predecessor to it (:func:`slot_steps`), each >= 1.
    last_ns : int
        Time of the pulse before the first, GPS ns.

    Returns
    -------
    slots : ndarray of complex64, shape (sum(steps), S)
        The pulses at their slots, zeros between (``rc`` as complex64 when no slot is
        empty).
    t_slots : ndarray of int64, shape (sum(steps),)
        Slot times, GPS ns: the pulses' own, an empty slot's interpolated linearly
        between the pulses around it.
    """
    offset = np.cumsum(steps)  # slot of each pulse, 1 = the slot after the last one
    n_new = int(offset[-1]) if offset.size else 0
    if n_new == rc.shape[0]:  # no pulse missing: the block is the slots
        return np.ascontiguousarray(rc, dtype=np.complex64), t_ns
    new = np.zeros((n_new, rc.shape[1]), np.complex64)
    new[offset - 1] = rc
    known = np.concatenate([[0], offset]).astype(np.float64)
    dt_known = np.concatenate([[0], t_ns - last_ns]).astype(np.float64)  # exact: small
    dt_new = np.interp(np.arange(1, n_new + 1), known, dt_known)
    return new, last_ns + np.rint(dt_new).astype(np.int64)


def _empty(n_samples: int) -> tuple[ComplexArray, IntArray]:
    return np.zeros((0, n_samples), np.complex64), np.zeros(0, np.int64)


def _concat(
    parts: list[tuple[ComplexArray, IntArray]], n_samples: int
) -> tuple[ComplexArray, IntArray]:
    data = [p[0] for p in parts if p[0].shape[0]]
    times = [p[1] for p in parts if p[1].shape[0]]
    if not data:
        return _empty(n_samples)
    return np.concatenate(data), np.concatenate(times)


def warm_up() -> None:
    """Compile the FIR kernel of :class:`AzimuthPrefilter` (or load it from numba's cache)
    by filtering 63 pulses of 4 samples, one slot empty, and flushing.

    numba compiles at a kernel's first call: seconds on an idle board, tens of seconds
    under load. The daemon calls this before it reads its links (``sarmoco run``).
    """
    pre = AzimuthPrefilter(1000.0, 50.0)
    pre.push(np.ones((63, 4), np.complex64), np.delete(1_000_000 * np.arange(64), 7))
    pre.flush()
