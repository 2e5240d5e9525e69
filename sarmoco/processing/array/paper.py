"""The array paper's Table 1 as an :class:`~sarmoco.processing.array.imaging3d.ArraySystem`.

Maximum look angle 20°, PRF 200 Hz, carrier 9.6 GHz, sampling 180 MHz, EPC spacing 0.02 m,
speed 100 m/s, pulse width 0.1 µs, altitude 200 m, bandwidth 150 MHz, 2 Tx × 80 Rx. The paper
gives no along-track element length; D = 1 m is the shortest whose Doppler band 2v/D fits
the PRF (0.5 m along-track resolution, the 0.5 m grid of its DEMs).
"""

from __future__ import annotations

import math

from sarmoco.errors import ProcessingError
from sarmoco.processing.array.geometry import mimo_layout
from sarmoco.processing.array.imaging3d import ArraySystem
from sarmoco.processing.types import C_MPS, RadarParams

PAPER_SPEED_MPS = 100.0
"""Platform speed of Table 1, m/s."""
PAPER_ALTITUDE_M = 200.0
"""Platform altitude of Table 1, m."""
PAPER_ROLL_DEG = 3.0
"""Roll of the paper's simulation, degrees."""


def paper_system(
    terrain_min_m: float,
    terrain_max_m: float,
    altitude_m: float = PAPER_ALTITUDE_M,
    n_rx: int = 80,
    n_tx: int = 2,
    margin_m: float = 6.0,
) -> ArraySystem:
    """Table 1's radar and array, with a receive window that spans the terrain.

    Parameters
    ----------
    terrain_min_m, terrain_max_m : float
        Lowest and highest terrain heights, m (the window runs from the nearest possible
        range, ``altitude - max``, to the farthest, ``(altitude - min) / cos(20° + 5°)``
        for rolls up to 5°, plus ``margin_m`` and a pulse length).
    altitude_m : float
        Platform height above the height datum, m.
    n_rx, n_tx : int
        Receivers and transmitters (scaled tests use fewer receivers).
    margin_m : float
        Extra range at both ends of the window, m.
    """
    if not altitude_m > terrain_max_m:
        raise ProcessingError(
            f"paper_system: altitude {altitude_m!r} m is not above the terrain {terrain_max_m!r} m"
        )
    look = math.radians(20.0)
    fs = 180e6
    tp = 0.1e-6
    near = altitude_m - terrain_max_m - margin_m
    far = (altitude_m - terrain_min_m) / math.cos(look + math.radians(5.0)) + margin_m
    n_samples = math.ceil((2.0 * (far - near) / C_MPS + tp) * fs)
    n_samples += n_samples % 2
    radar = RadarParams(
        carrier_hz=9.6e9,
        bandwidth_hz=150e6,
        pulse_width_s=tp,
        sample_rate_hz=fs,
        prf_hz=200.0,
        n_samples=n_samples,
        range_gate_delay_s=2.0 * near / C_MPS,
    )
    return ArraySystem(radar, mimo_layout(n_tx, n_rx, 0.02), 1.0, look)
