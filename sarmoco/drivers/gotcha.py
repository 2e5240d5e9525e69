"""Reader for the AFRL GOTCHA volumetric SAR phase history (``data_3dsar_*.mat``).

Each file holds one degree of azimuth of one pass and polarisation as a MATLAB
struct ``data`` with (per the AFRL readme, checked against the files):

- ``fp`` (K, Np) complex: phase history, frequency-major, deramped
  (motion compensated) to the scene centre: a scatterer at range ``R`` from
  the antenna contributes ``exp(-j 4 pi f (R - r0) / c)``;
- ``freq`` (K, 1): frequency of each row, Hz (X band, ~640 MHz);
- ``x``, ``y``, ``z`` (1, Np): antenna position, m, in a local scene frame
  whose origin is the scene centre, z up;
- ``r0`` (1, Np): range from the antenna to the scene centre, m;
- ``th`` (1, Np): azimuth angle, deg; ``phi`` (1, Np): elevation angle, deg;
- ``af``: the provider's autofocus solution, ``r_correct`` (1, Np) m and
  ``ph_correct`` (1, Np) rad, applied as ``R0 = r0 + r_correct`` and
  ``fp * exp(j ph_correct)`` (the convention of AFRL's own toolbox).

:func:`read_gotcha` returns the pulses pulse-major, in file order, as plain
numpy arrays; it does not apply the autofocus solution.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.io

from sarmoco.errors import DataFileError

_FIELDS = ("fp", "freq", "x", "y", "z", "r0", "th", "phi", "af")


@dataclass(frozen=True)
class GotchaPass:
    """Phase history of one or more consecutive GOTCHA files.

    Parameters
    ----------
    phase_history : ndarray of complex64, shape (P, F)
        Pulse-major phase history deramped to the scene centre.
    freq_hz : ndarray of float64, shape (F,)
        Frequency of each column, Hz, ascending.
    apc_m : ndarray of float64, shape (P, 3)
        Antenna position (x, y, z up) in the scene frame, m.
    r0_m : ndarray of float64, shape (P,)
        Range to the scene centre (the deramp range), m.
    azimuth_deg, elevation_deg : ndarray of float64, shape (P,)
        Provider's aspect angles, deg.
    af_r_correct_m : ndarray of float64, shape (P,)
        Autofocus range correction, m (add to ``r0_m``).
    af_ph_correct_rad : ndarray of float64, shape (P,)
        Autofocus phase correction, rad (multiply pulses by ``exp(j ph)``).
    """

    phase_history: npt.NDArray[np.complex64]
    freq_hz: npt.NDArray[np.float64]
    apc_m: npt.NDArray[np.float64]
    r0_m: npt.NDArray[np.float64]
    azimuth_deg: npt.NDArray[np.float64]
    elevation_deg: npt.NDArray[np.float64]
    af_r_correct_m: npt.NDArray[np.float64]
    af_ph_correct_rad: npt.NDArray[np.float64]


def _row(rec: Any, name: str, path: Path, n: int) -> npt.NDArray[np.float64]:
    v = np.asarray(rec[name], dtype=np.float64).ravel()
    if v.shape != (n,):
        raise DataFileError(f"{path}: data.{name} has {v.size} values, expected {n}")
    return v


def _read_one(path: Path) -> GotchaPass:
    try:
        mat = scipy.io.loadmat(str(path), squeeze_me=False)
    except (OSError, ValueError, NotImplementedError) as exc:
        raise DataFileError(f"{path}: not a readable MATLAB v5 file ({exc})") from exc
    if "data" not in mat or mat["data"].dtype.names is None:
        raise DataFileError(f"{path}: no struct 'data'")
    rec = mat["data"][0, 0]
    missing = [f for f in _FIELDS if f not in mat["data"].dtype.names]
    if missing:
        raise DataFileError(f"{path}: data lacks field(s) {missing}")
    fp = np.asarray(rec["fp"])
    if fp.ndim != 2 or not np.iscomplexobj(fp):
        raise DataFileError(f"{path}: data.fp is not a complex 2-D array")
    n_f, n_p = fp.shape
    freq = np.asarray(rec["freq"], dtype=np.float64).ravel()
    if freq.shape != (n_f,):
        raise DataFileError(f"{path}: data.freq has {freq.size} values, fp has {n_f} rows")
    af = rec["af"]
    if af.dtype.names is None or not {"r_correct", "ph_correct"} <= set(af.dtype.names):
        raise DataFileError(f"{path}: data.af lacks r_correct / ph_correct")
    af = af[0, 0]
    return GotchaPass(
        phase_history=np.ascontiguousarray(fp.T, dtype=np.complex64),
        freq_hz=freq,
        apc_m=np.stack([_row(rec, k, path, n_p) for k in ("x", "y", "z")], axis=1),
        r0_m=_row(rec, "r0", path, n_p),
        azimuth_deg=_row(rec, "th", path, n_p),
        elevation_deg=_row(rec, "phi", path, n_p),
        af_r_correct_m=_row(af, "r_correct", path, n_p),
        af_ph_correct_rad=_row(af, "ph_correct", path, n_p),
    )


def read_gotcha(paths: Sequence[Path]) -> GotchaPass:
    """Read and concatenate GOTCHA files (consecutive azimuth degrees of one pass).

    Parameters
    ----------
    paths : sequence of Path
        ``data_3dsar_pass*_az*_*.mat`` files in azimuth order.

    Returns
    -------
    GotchaPass

    Raises
    ------
    DataFileError
        A file is missing, unreadable, lacks a field, or the files disagree on
        the frequencies.
    """
    if not paths:
        raise DataFileError("read_gotcha: no files given")
    parts = [_read_one(Path(p)) for p in paths]
    for p, part in zip(paths[1:], parts[1:], strict=True):
        if not np.array_equal(part.freq_hz, parts[0].freq_hz):
            raise DataFileError(f"{p}: frequencies differ from {paths[0]}")
    return GotchaPass(
        phase_history=np.concatenate([q.phase_history for q in parts], axis=0),
        freq_hz=parts[0].freq_hz,
        apc_m=np.concatenate([q.apc_m for q in parts], axis=0),
        r0_m=np.concatenate([q.r0_m for q in parts]),
        azimuth_deg=np.concatenate([q.azimuth_deg for q in parts]),
        elevation_deg=np.concatenate([q.elevation_deg for q in parts]),
        af_r_correct_m=np.concatenate([q.af_r_correct_m for q in parts]),
        af_ph_correct_rad=np.concatenate([q.af_ph_correct_rad for q in parts]),
    )
