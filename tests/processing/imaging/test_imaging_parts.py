"""Building blocks of image formation: grid, interpolation, phase-history conversions."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging import (
    PlaneGrid,
    compressed_from_phase_history,
    facing_heading,
    phase_history_from_compressed,
)
from sarmoco.processing.imaging.backprojection import ROW_BLOCK, task_order
from sarmoco.processing.imaging.interp import fft_upsample, sinc_interp, sinc_interp_columns
from sarmoco.processing.types import C_MPS


def _tones(n: int, freqs: np.ndarray, pos: np.ndarray) -> np.ndarray:
    return np.exp(2j * np.pi * freqs[:, None] * pos)


def test_sinc_interp_band_limited_tones() -> None:
    freqs = np.array([-0.35, -0.1, 0.0, 0.2, 0.38])  # cycles per sample, |f| < 0.4
    x = _tones(256, freqs, np.arange(256.0))
    pos = np.tile(np.linspace(20.0, 230.0, 97), (freqs.size, 1))
    got = sinc_interp(x, pos, taps=16)
    assert np.max(np.abs(got - _tones(256, freqs, pos[0]))) < 4e-3


def test_shared_positions_give_the_per_row_sums() -> None:
    # positions shared by every row (one row of them), or by every column (along axis 0):
    # the same kernel and sums as the positions repeated for each row, to the last bit
    freqs = np.array([-0.3, 0.05, 0.37])
    x = _tones(200, freqs, np.arange(200.0)).astype(np.complex64)
    pos = np.concatenate([[-1.0, 0.0], np.linspace(3.3, 196.7, 61), [199.0, 199.5]])
    full = sinc_interp(x, np.tile(pos, (freqs.size, 1)))
    assert np.array_equal(sinc_interp(x, pos[None, :]), full)
    columns = sinc_interp_columns(np.ascontiguousarray(x.T), pos)
    assert columns.dtype == np.complex64 and columns.shape == (pos.size, freqs.size)
    assert np.array_equal(columns, full.T)
    assert np.all(columns[[0, -1]] == 0)  # outside [0, N - 1]
    inside = (pos >= 8.0) & (pos <= 191.0)  # the kernel's taps all within the samples
    assert np.max(np.abs(columns[inside].T - _tones(200, freqs, pos[inside]))) < 4e-3
    with pytest.raises(ProcessingError):
        sinc_interp(x, np.zeros((2, 4)))  # neither one row nor one per row


def test_sinc_interp_outside_is_zero_and_rejects_odd_taps() -> None:
    x = np.ones((1, 8), dtype=np.complex64)
    got = sinc_interp(x, np.array([[-0.5, 7.5]]), taps=8)
    assert np.all(got == 0)
    assert got.dtype == np.complex64
    with pytest.raises(ProcessingError):
        sinc_interp(x, np.zeros((1, 1)), taps=7)


@pytest.mark.parametrize("n", [64, 65])
def test_fft_upsample(n: int) -> None:
    freqs = np.array([-0.3, 0.1, 0.33])
    x = _tones(n, freqs, np.arange(n) * 1.0)
    # periodic tones (integer cycles per n) are reproduced exactly between samples
    freqs_p = np.round(freqs * n) / n
    xp = _tones(n, freqs_p, np.arange(n) * 1.0)
    up = fft_upsample(xp, 4)
    assert np.allclose(up[:, ::4], xp, atol=1e-12)
    assert np.allclose(up, _tones(n, freqs_p, np.arange(4 * n) / 4.0), atol=1e-10)
    assert fft_upsample(x, 1) is x


def test_grid_positions_and_heading() -> None:
    g = PlaneGrid.centred((10.0, 20.0, -3.0), 4, 6, 0.5, 0.25, heading_rad=np.pi / 2)
    pos = g.positions()
    assert pos.shape == (4, 6, 3)
    assert np.allclose(pos[2, 3], [10.0, 20.0, -3.0])
    assert np.allclose(pos[3, 3] - pos[2, 3], [0.0, 0.5, 0.0])  # e0 = +y
    assert np.allclose(pos[2, 4] - pos[2, 3], [-0.25, 0.0, 0.0])  # e1 = -x
    apc = np.array([[1000.0, 0.0, 500.0], [1000.0, 10.0, 500.0]])
    h = facing_heading(apc, (0.0, 0.0, 0.0))
    _, e1 = PlaneGrid(g.axis0_m, g.axis1_m, heading_rad=h).unit_vectors
    assert e1[0] == pytest.approx(-1.0, abs=1e-4)
    with pytest.raises(ProcessingError):
        PlaneGrid(np.array([0.0, 1.0, 3.0]), g.axis1_m)


def test_phase_history_round_trip() -> None:
    """A target's compressed line -> phase history -> compressed line keeps range and phase."""
    fc, bw = 10e9, 500e6
    n_f = 256
    freq = fc + (np.arange(n_f) - n_f // 2) * bw / n_f
    ref = np.array([1000.0, 1000.5])
    r_t = np.array([1003.1, 1002.7])
    ph = np.exp(-4j * np.pi * freq[None, :] * (r_t - ref)[:, None] / C_MPS)
    rc, r_axis, fc_out = compressed_from_phase_history(ph, freq, upsample=8)
    assert fc_out == pytest.approx(fc)
    for p in range(2):
        i = int(np.argmax(np.abs(rc[p])))
        assert r_axis[i] == pytest.approx(r_t[p] - ref[p], abs=C_MPS / (2 * bw) / 8)
        expect = np.exp(-4j * np.pi * fc * (r_t[p] - ref[p]) / C_MPS)
        assert np.angle(rc[p, i] / expect) == pytest.approx(0.0, abs=0.25)
    # back to the phase history: the relative axis and phase need no deramp (ref 0)
    ph2, freq2 = phase_history_from_compressed(rc, r_axis, fc_out, bw, np.zeros(2))
    assert np.allclose(freq2[:n_f], freq)
    assert np.allclose(ph2[:, :n_f] / rc.shape[1], ph, atol=1e-4)
    assert np.allclose(ph2[:, n_f:], 0.0, atol=1e-4)


@pytest.mark.parametrize("n_rows", [1, 7, 8, 9, 1200, 1201])
def test_each_thread_shares_the_whole_grid(n_rows: int) -> None:
    """numba gives each thread one contiguous run of a ``prange``'s tasks; a block of pulses
    lights only the rows under its beam, so each run must hold blocks from the whole grid
    (every block once), or one thread works while the other waits."""
    threads = numba.get_num_threads()
    order = task_order(n_rows, ROW_BLOCK)
    n_blocks = -(-n_rows // ROW_BLOCK)
    assert sorted(order.tolist()) == list(range(n_blocks))
    for run in np.array_split(order, threads):
        if n_blocks >= 2 * threads and run.size:
            assert run.min() < threads and run.max() >= n_blocks - threads
