"""OFIR ([PaleRamon-BBox] Alg. 2) with the data-linear horizon-start prior: kernel form vs the literal iterative
algorithm, the two OUFIR limits of the prior, the steady-state KF limit, batching, finiteness, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.filters.ofir import default_prior, ofir_gain, ofir_iterative
from bboxtune.filters.oufir import oufir_gain
from tests.filters.test_oufir import TAU, B, F, H, assert_close_rel, simulate, steady_state_kf


@pytest.fixture(scope="module")
def track() -> np.ndarray:
    y = simulate(np.random.default_rng(2), 150)
    y[[0, 10, 50, 51, 52, 53, 90, 149]] = np.nan
    return y


@pytest.mark.parametrize("N", [2, 3, 5, 20, 60, 200])
@pytest.mark.parametrize("P0", [None, np.diag([25.0, 900.0])])
def test_kernel_form_equals_iterative_alg2(track: np.ndarray, N: int, P0: np.ndarray | None) -> None:
    """Every frame (start-up, NaN windows, unobservable frames, full windows) against Alg. 2 run literally."""
    fast = filters.make("ofir", filters.constant_velocity(TAU), sigma_w=50.0, sigma_v=4.0, horizon=N,
                        P0=P0).run(track[:, None])
    ref = ofir_iterative(track, F, H, B, N, 50.0, 4.0, default_prior(4.0, TAU) if P0 is None else P0)
    assert np.isnan(fast[0]).all() and np.isnan(ref[0]).all()
    assert_close_rel(fast[1:], ref[1:], 1e-8)


@pytest.mark.parametrize("valid_drop", [[], [0, 1, 9]])
def test_prior_limits_give_oufir(valid_drop: list[int]) -> None:
    """P0 = diag(σ_v², p), p → ∞: y_m acts as a plain measurement → OUFIR on the window (error ∝ 1/p);
    P0 = p I, p → ∞ (P_m⁻¹ → 0): y_m is ignored → OUFIR on the samples after it."""
    valid = np.ones(25, bool)
    valid[valid_drop] = False
    a = int(np.argmax(valid))
    after = valid.copy()
    after[a] = False
    W_ufir = oufir_gain(F, H, B, valid, 50.0, 4.0)
    W_ufir_after = oufir_gain(F, H, B, after, 50.0, 4.0)
    errors = []
    for p in (1e4, 1e8):
        errors.append(np.abs(ofir_gain(F, H, B, valid, 50.0, 4.0, np.diag([16.0, p])) - W_ufir).max())
        assert np.abs(ofir_gain(F, H, B, valid, 50.0, 4.0, p * np.eye(2)) - W_ufir_after).max() < 10 / p
    assert 1e-6 < errors[0] and errors[1] < 2e-4 * errors[0]  # shrinks like 1/p
    assert np.abs(ofir_gain(F, H, B, valid, 50.0, 4.0, default_prior(4.0, TAU)) - W_ufir).max() > 1e-4


def test_constant_track_reproduced_and_gain_sums() -> None:
    """The data-linear prior keeps OFIR translation-equivariant (position gain sums to 1, velocity to 0),
    but a confident velocity prior (0 ± 1 unit/s) biases it on ramps, unlike OUFIR."""
    valid = np.ones(30, bool)
    valid[[0, 4]] = False
    W = ofir_gain(F, H, B, valid, 50.0, 4.0, default_prior(4.0, TAU))
    np.testing.assert_allclose(W.sum(axis=1), [1.0, 0.0], atol=1e-10)
    assert np.all(W[:, ~valid] == 0)
    ramp = 7.0 * TAU * np.arange(30)
    assert abs(ofir_gain(F, H, B, valid, 50.0, 4.0, np.diag([16.0, 1.0]))[0] @ ramp - ramp[-1]) > 0.05


def test_recursive_frames_equal_batch_gains() -> None:
    """Start-up frames and NaN windows (Kalman recursion on the data) equal each window's batch gain."""
    y = simulate(np.random.default_rng(10), 70)
    y[[0, 3, 4, 40, 66]] = np.nan
    N, P0 = 30, np.diag([9.0, 100.0])
    out = filters.make("ofir", filters.constant_velocity(TAU), sigma_w=20.0, sigma_v=3.0, horizon=N, P0=P0).run(
        y[:, None])
    valid = np.isfinite(y)
    y0 = np.where(valid, y, 0.0)
    for n in range(2, 70):
        m = max(0, n - N + 1)
        W = ofir_gain(F, H, B, valid[m: n + 1], 20.0, 3.0, P0)
        np.testing.assert_allclose(out[n], W @ y0[m: n + 1], rtol=1e-10, atol=1e-9)


def test_long_horizon_converges_to_steady_state_kf() -> None:
    """The prior is forgotten geometrically: at N = 160 the kernel equals the truncated steady-state KF impulse
    response to 3.8e-9 (newest tap 4e-13), as OUFIR does (notes §3)."""
    K, A = steady_state_kf(50.0, 4.0)
    W = ofir_gain(F, H, B, np.ones(160, bool), 50.0, 4.0, default_prior(4.0, TAU))
    W_kf = np.stack([np.linalg.matrix_power(A, k) @ K for k in range(160)][::-1], axis=1)
    assert np.abs(W - W_kf).max() < 1e-8
    assert np.abs(W[:, -1] - K).max() < 1e-11




@pytest.mark.parametrize("params, name", [
    ({"horizon": 1}, "horizon"), ({"sigma_w": -2.0}, "sigma_w"), ({"sigma_v": np.nan}, "sigma_v"),
    ({"P0": np.eye(3)}, "P0"), ({"P0": np.array([[1.0, 2.0], [2.0, 1.0]])}, "P0"),
    ({"P0": np.array([[1.0, 0.5], [0.0, 1.0]])}, "P0"), ({"P0": np.diag([1.0, np.inf])}, "P0"),
])
def test_bad_parameters_raise_value_error_naming_them(params: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        filters.make("ofir", filters.constant_velocity(TAU), **params)
