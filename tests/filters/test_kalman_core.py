"""The one-row Python-float gain recursion equals the batched numpy recursion to rounding (with KF-CMN's
gap-length kinds), blocks of frames equal the frame-by-frame affine recursion, frame units."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.filters import kalman_core as kc
from bboxtune.filters.kf_cmn import cmn_tables, differenced_kinds


@pytest.mark.parametrize("psi", [0.0, 0.6, 0.95])
def test_one_row_recursion_equals_batched(psi: float) -> None:
    axis = filters.constant_velocity(0.05).axis()
    rng = np.random.default_rng(int(psi * 100))
    finite = rng.random((2, 300)) > 0.1
    finite[:, :3] = False  # WAIT frames before the first measurement, then INIT
    finite[1, 100:140] = False  # a long gap besides the short ones
    z = np.where(finite, 1.0, np.nan)
    kinds, gaps, _ = differenced_kinds(kc.frame_kinds(finite, prior=False), z, finite, np.full(2, np.nan),
                                       np.zeros(2, np.int64), np.full(2, psi))
    assert gaps[0] == 0 and gaps.max() >= 40 and kinds.max() == kc.UPDATE_Z + len(gaps) - 1
    params = np.array([[50.0, 4.0, psi], [50.0, 4.0, psi]])
    tables = cmn_tables(axis, params, gaps)
    P_start = np.broadcast_to(np.diag([16.0, 1e8])[:, :, None], (2, 2, 2)).copy()
    coef_b, steady_b, P_b = kc.gain_recursion(kinds, tables, P_start)  # G = 2: batched path
    for g in range(2):
        one = kc.StepTables(*(t[..., g:g + 1] for t in (tables.A, tables.Q, tables.Lam, tables.D, tables.R, tables.M)))
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


@pytest.mark.parametrize("name", ["kf", "kf_cmn"])
@pytest.mark.parametrize("prior", [False, True])
def test_frame_units_give_the_same_estimates(name: str, prior: bool) -> None:
    """IN_FRAMES: the run at τ = 1 with params_in_frames equals the run at τ (positions; velocities × τ), also
    with a prior and missing frames — what lets envs batch tracks of different τ in one call."""
    cls = filters.filter_class(name)
    assert cls.IN_FRAMES
    rng = np.random.default_rng(3)
    y = np.cumsum(rng.normal(size=(3, 120, 2)), axis=1) * 2.0 + 50.0
    y[1, 30:37] = np.nan
    tau = 0.037
    params = {"sigma_w": np.array([30.0, 200.0, 5.0]), "sigma_v": np.array([2.0, 3.0, 1.0])}
    if name == "kf_cmn":
        params["psi"] = np.array([0.3, 0.9, 0.0])
    if prior:
        params.update(x0=np.array([50.0, 50.0, 3.0, -2.0]), P0=np.diag([4.0, 4.0, 100.0, 100.0]))
    at_tau = filters.make(name, filters.constant_velocity(tau, 2), **params).run(y)
    in_frames = filters.make(name, filters.constant_velocity(1.0, 2), **cls.params_in_frames(params, tau)).run(y)
    np.testing.assert_allclose(in_frames[..., :2], at_tau[..., :2], rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(in_frames[..., 2:], at_tau[..., 2:] * tau, rtol=1e-8, atol=1e-8)
    if prior:
        with pytest.raises(ValueError, match="one prior for all tracks"):
            cls.params_in_frames(params, np.array([0.1, 0.2, 0.3]))
