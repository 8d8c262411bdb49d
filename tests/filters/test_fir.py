"""Kwon's FIR ([Mo-FIR] eqs. 5–13): the literal formula, equality with OUFIR (gain and run), [Mo-FIR]'s
sampling-time-error setting, the steady-state KF limit, batching, finiteness, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.filters.fir import kwon_gain
from bboxtune.filters.oufir import oufir_gain, oufir_iterative
from tests.filters.test_oufir import TAU, B, F, H, assert_close_rel, simulate, steady_state_kf


def kwon_literal(L: int, sigma_w: float, sigma_v: float) -> np.ndarray:
    """Eqs. (5)–(13) typed out with explicit inverses (oracle for small L)."""
    Fp = [np.linalg.matrix_power(F, k) for k in range(L)]
    C_N = np.vstack([H @ Fp[i] for i in range(L)])  # (11)
    G_N = np.array([[(H @ Fp[i - j] @ B)[0, 0] if j <= i else 0.0 for j in range(1, L)] for i in range(L)])  # (12)
    M_N = np.hstack([Fp[L - 1 - j] @ B for j in range(1, L)])  # (13)
    A_inv = np.linalg.inv(Fp[L - 1])
    C_bar = C_N @ A_inv  # (7)
    G_bar = G_N - C_N @ A_inv @ M_N  # (8)
    Pi = G_bar @ (sigma_w**2 * np.eye(L - 1)) @ G_bar.T + sigma_v**2 * np.eye(L)  # (9)
    Pi_inv = np.linalg.inv(Pi)
    return np.linalg.inv(C_bar.T @ Pi_inv @ C_bar) @ C_bar.T @ Pi_inv  # (5)


@pytest.mark.parametrize("L", [2, 3, 6, 12])
def test_gain_equals_literal_equations(L: int) -> None:
    W = kwon_gain(F, H, B, np.ones(L, bool), 50.0, 4.0)
    np.testing.assert_allclose(W, kwon_literal(L, 50.0, 4.0), atol=1e-9 * np.abs(W).max())


@pytest.mark.parametrize("L", [2, 3, 5, 20, 60, 160])
@pytest.mark.parametrize("sigma_w, sigma_v", [(50.0, 4.0), (1.0, 1.0), (1e-3, 10.0)])
@pytest.mark.parametrize("drop", [[], [0, 1], [1, -2]])
def test_gain_equals_oufir_gain(L: int, sigma_w: float, sigma_v: float, drop: list[int]) -> None:
    """Two formulas, one estimator (notes §1.7): measured ≤ 2.8e-12 of the largest tap over these cases."""
    valid = np.ones(L, bool)
    if L > 4:
        valid[drop] = False
    W_kwon = kwon_gain(F, H, B, valid, sigma_w, sigma_v)
    W_oufir = oufir_gain(F, H, B, valid, sigma_w, sigma_v)
    np.testing.assert_allclose(W_kwon, W_oufir, atol=1e-11 * np.abs(W_oufir).max())


@pytest.fixture(scope="module")
def track() -> np.ndarray:
    y = simulate(np.random.default_rng(6), 150)
    y[[0, 10, 50, 51, 52, 53, 90, 149]] = np.nan
    return y


@pytest.mark.parametrize("N", [2, 5, 20, 60, 200])
def test_run_equals_iterative_oufir(track: np.ndarray, N: int) -> None:
    fast = filters.make("fir", filters.constant_velocity(TAU), sigma_w=50.0, sigma_v=4.0, horizon=N).run(
        track[:, None])
    ref = oufir_iterative(track, F, H, B, N, 50.0, 4.0)
    assert np.isnan(fast[0]).all()
    assert_close_rel(fast[1:], ref[1:], 1e-8)


@pytest.mark.parametrize("delta", [0.0, 0.01, -0.02, 0.5])
def test_sampling_time_error_keeps_straight_lines_exact(delta: float) -> None:
    """[Mo-FIR] §III: the truth advances every τ + δ while the filter assumes τ. For constant-velocity motion the
    FIR position stays exact (unbiased for every line) and the velocity is scaled by (τ + δ)/τ."""
    t = (TAU + delta) * np.arange(60)
    y = 40.0 + 12.0 * t
    out = filters.make("fir", filters.constant_velocity(TAU), sigma_w=3.0, sigma_v=2.0, horizon=15).run(y[:, None])
    np.testing.assert_allclose(out[1:, 0], y[1:], atol=1e-9 * np.abs(y).max())
    np.testing.assert_allclose(out[1:, 1], 12.0 * (TAU + delta) / TAU, rtol=1e-8)


def test_long_horizon_converges_to_steady_state_kf() -> None:
    """N = 160: kernel = truncated steady-state KF impulse response to 3.8e-9, newest tap to 1.3e-14."""
    K, A = steady_state_kf(50.0, 4.0)
    W = kwon_gain(F, H, B, np.ones(160, bool), 50.0, 4.0)
    W_kf = np.stack([np.linalg.matrix_power(A, k) @ K for k in range(160)][::-1], axis=1)
    assert np.abs(W - W_kf).max() < 1e-8
    assert np.abs(W[:, -1] - K).max() < 1e-11




@pytest.mark.parametrize("ratio", [1e4, 1e12])
def test_ill_conditioned_pi_falls_back_to_equal_estimator(ratio: float) -> None:
    W = kwon_gain(F, H, B, np.ones(300, bool), ratio, 1.0)
    assert np.all(np.isfinite(W))
    np.testing.assert_allclose(W, oufir_gain(F, H, B, np.ones(300, bool), ratio, 1.0), atol=1e-9 * np.abs(W).max())


@pytest.mark.parametrize("params, name", [
    ({"horizon": 0}, "horizon"), ({"horizon": 1e6}, "horizon"), ({"sigma_w": np.inf}, "sigma_w"),
    ({"sigma_v": 0.0}, "sigma_v"), ({"sigma_v": np.ones(2), "horizon": np.array([5, 6, 7])}, "horizon"),
])
def test_bad_parameters_raise_value_error_naming_them(params: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        filters.make("fir", filters.constant_velocity(TAU), **params)
