"""The one-row Python-float gain recursion equals the batched numpy recursion to rounding."""

from __future__ import annotations

import numpy as np
import pytest

import filters
from filters import kalman_core as kc
from filters.kf_cmn import cmn_tables


@pytest.mark.parametrize("psi", [0.0, 0.6, 0.95])
def test_one_row_recursion_equals_batched(psi: float) -> None:
    axis = filters.constant_velocity(0.05).axis()
    rng = np.random.default_rng(int(psi * 100))
    finite = rng.random((2, 300)) > 0.1
    finite[:, :3] = False  # WAIT frames before the first measurement, then INIT
    kinds = kc.frame_kinds(finite, prior=False, differenced=psi > 0)
    params = np.array([[50.0, 4.0, psi], [50.0, 4.0, psi]])
    tables = cmn_tables(axis, params)
    P_start = np.broadcast_to(np.diag([16.0, 1e8])[:, :, None], (2, 2, 2)).copy()
    coef_b, steady_b, P_b = kc.gain_recursion(kinds, tables, P_start)  # G = 2: batched path
    for g in range(2):
        one = kc.StepTables(*(t[..., g:g + 1] for t in (tables.A, tables.Q, tables.Lam, tables.D, tables.R)))
        coef_1, steady_1, P_1 = kc.gain_recursion(kinds[g:g + 1], one, P_start[:, :, g:g + 1])
        stop = min(steady_1, steady_b)
        np.testing.assert_allclose(coef_1[:stop + 1, :, 0], coef_b[:stop + 1, :, g], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(P_1[:, :, 0], P_b[:, :, g], rtol=1e-12)


@pytest.mark.parametrize("T", [1, 7, 16, 53])
def test_blocks_of_frames_equal_the_frame_by_frame_affine_recursion(T: int) -> None:
    rng = np.random.default_rng(T)
    coef = np.concatenate([rng.uniform(-0.6, 0.6, (T, 4)) + [0.3, 0.0, 0.0, 0.3], rng.normal(size=(T, 2))], axis=1)
    coef[T // 3] = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]  # an INIT frame: x = [m, 0], the past forgotten
    m = rng.normal(100.0, 30.0, (T, 5))
    x_start = rng.normal(size=(2, 5))
    want, x = np.empty((T, 2, 5)), x_start
    for n in range(T):  # the literal recursion x_n = M_n x_{n−1} + g_n m_n
        x = coef[n, :4].reshape(2, 2) @ x + coef[n, 4:, None] * m[n]
        want[n] = x
    np.testing.assert_allclose(kc._affine_blocks(coef, x_start, m), want, rtol=1e-12, atol=1e-10)
