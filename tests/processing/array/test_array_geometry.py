"""Array geometry: EPCs and their bistatic correction, the virtual array, exterior orientation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sarmoco.drivers.attitude import euler_to_quat as scalar_euler_to_quat
from sarmoco.errors import ProcessingError
from sarmoco.processing.array.geometry import (
    ArrayLayout,
    attitude_matrix,
    bistatic_residual_m,
    element_positions_ned,
    euler_to_quat,
    mimo_layout,
)
from sarmoco.processing.geometry import quat_to_matrix


def test_epc_plus_bistatic_correction_equals_true_bistatic_ranges() -> None:
    layout = mimo_layout(2, 80, 0.02)
    m, n = layout.pair_indices()
    rng = np.random.default_rng(3)
    # ground points 150..260 m below, up to 25 deg off nadir, a few m along track
    look = rng.uniform(-0.44, 0.44, 200)
    rho = rng.uniform(150.0, 260.0, 200)
    pts = np.stack([rng.uniform(-5, 5, 200), rho * np.sin(look), rho * np.cos(look)], axis=1)
    tx = layout.tx_body_m[m][:, None, :]
    rx = layout.rx_body_m[n][:, None, :]
    epc = layout.epc_body_m[:, None, :]
    r_t = np.linalg.norm(pts[None] - tx, axis=-1)
    r_r = np.linalg.norm(pts[None] - rx, axis=-1)
    r_e = np.linalg.norm(pts[None] - epc, axis=-1)
    baseline_dir = (rx - tx) / np.maximum(layout.baseline_m[:, None, None], 1e-12)
    cos_psi = np.sum((pts[None] - epc) * baseline_dir, axis=-1) / r_e
    bistatic = 0.5 * (r_t + r_r)
    corrected = r_e + bistatic_residual_m(layout.baseline_m[:, None], r_e, cos_psi)
    # the residual matters (mm at the array's ends: 2.5 rad two-way at 9.6 GHz) ...
    assert np.max(np.abs(bistatic - r_e)) > 5e-3
    # ... and the corrected EPC range equals the bistatic one to 1e-6 m (0.0004 rad)
    assert np.max(np.abs(bistatic - corrected)) < 1e-6


def test_virtual_array_is_uniform_and_tx_major() -> None:
    layout = mimo_layout(2, 80, 0.02)
    y, d = layout.virtual_array()
    assert layout.n_channels == 160
    assert d == pytest.approx(0.02)
    # tx-major: channel m*N + n, EPCs increasing, centred
    np.testing.assert_allclose(y, (np.arange(160) - 79.5) * 0.02, atol=1e-12)
    assert layout.pair_indices()[0][80] == 1 and layout.pair_indices()[1][80] == 0


def test_non_uniform_or_off_line_array_is_refused() -> None:
    tx = np.zeros((1, 3))
    rx = np.array([[0.0, 0.0, 0.0], [0.0, 0.04, 0.0], [0.0, 0.10, 0.0]])
    with pytest.raises(ProcessingError, match="uniform"):
        ArrayLayout(tx, rx).virtual_array()
    rx_bent = np.array([[0.0, 0.0, 0.0], [0.0, 0.04, 0.0], [0.01, 0.08, 0.0]])
    with pytest.raises(ProcessingError, match="one line"):
        ArrayLayout(tx, rx_bent).virtual_array()
    with pytest.raises(ProcessingError, match="rx_body_m"):
        ArrayLayout(tx, np.zeros((3, 2)))


def test_attitude_matrix_is_r_kappa_r_omega_r_alpha_of_the_ins_quaternion() -> None:
    rng = np.random.default_rng(5)
    angles = rng.uniform(-0.6, 0.6, (20, 3))
    mats = attitude_matrix(angles[:, 0], angles[:, 1], angles[:, 2])
    quats = euler_to_quat(angles[:, 0], angles[:, 1], angles[:, 2])
    np.testing.assert_allclose(quat_to_matrix(quats), mats, atol=1e-12)
    for (roll, pitch, yaw), q in zip(angles, quats, strict=True):
        np.testing.assert_allclose(scalar_euler_to_quat(roll, pitch, yaw), q, atol=1e-12)


def test_roll_moves_the_right_wing_down() -> None:
    alpha = math.radians(3.0)
    pos = np.array([[10.0, 20.0, -200.0]])
    quat = euler_to_quat(alpha, 0.0, 0.0)[None, :]
    body = np.array([[0.0, 1.5, 0.0]])
    got = element_positions_ned(pos, quat, body)[0, 0]
    # the paper: (x, y cos a, y sin a) with the down axis positive
    np.testing.assert_allclose(got - pos[0], [0.0, 1.5 * math.cos(alpha), 1.5 * math.sin(alpha)])
