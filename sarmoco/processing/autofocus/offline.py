"""Two-step autofocus of a whole aperture at once (the streaming engine, fed everything)."""

from __future__ import annotations

import dataclasses
import math

from sarmoco.errors import ProcessingError
from sarmoco.processing.autofocus.corrections import Corrections
from sarmoco.processing.autofocus.report import AutofocusReport
from sarmoco.processing.autofocus.settings import AutofocusConfig, AutofocusGeometry
from sarmoco.processing.autofocus.streaming import SlidingSubapertureAutofocus
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray


def autofocus_offline(
    rc: ComplexArray,
    t_ns: IntArray,
    range_m: FloatArray,
    geometry: AutofocusGeometry,
    config: AutofocusConfig,
) -> tuple[Corrections, AutofocusReport]:
    """Two-step autofocus of a whole aperture (constant and linear terms pinned to zero mean
    and zero trend between the first and the last subaperture centre).

    The streaming engine fed the whole aperture at once with an unbounded pin window: the
    estimates are the streaming ones by construction, and the pin window is the aperture's.

    Parameters
    ----------
    rc : ndarray, shape (P, S)
        Navigation-compensated range-compressed pulses.
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    range_m : ndarray, shape (S,)
        Uniform slant-range axis, m.
    geometry, config
        See :class:`AutofocusGeometry`, :class:`AutofocusConfig`.

    Returns
    -------
    Corrections, AutofocusReport
    """
    engine = SlidingSubapertureAutofocus(
        geometry, range_m, dataclasses.replace(config, pin_window_s=math.inf)
    )
    engine.extend(rc, t_ns)
    corr = engine.take_corrections(flushing=True)[1]
    if not engine.report.subapertures:
        raise ProcessingError(
            f"autofocus_offline: {(int(t_ns[-1]) - int(t_ns[0])) * 1e-9:.3f} s of data is "
            f"shorter than a subaperture ({config.subaperture_s} s)"
        )
    return corr, engine.report
