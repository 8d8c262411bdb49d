"""OUFIR ([PaleRamon-BBox] Alg. 4): kernel form vs the literal iterative algorithm, unbiasedness, the steady-state KF
limit, both numerical branches of the batch gain, batching/per-track parameters, finiteness, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from hypothesis import given, settings
from hypothesis import strategies as st

import bboxtune.filters.oufir as oufir
from bboxtune import filters
from bboxtune.filters.oufir import kf_step, oufir_gain, oufir_iterative, window_gls_gain

TAU = 0.05
AXIS = filters.constant_velocity(TAU).axis()
F, H, B = AXIS.F, AXIS.H, AXIS.B


def simulate(rng: np.random.Generator, T: int, sigma_w: float = 50.0, sigma_v: float = 4.0,
             x0: tuple[float, float] = (100.0, 20.0)) -> np.ndarray:
    """One CV track of the axis model (τ = TAU): measurements (T,)."""
    x = np.empty((T, 2))
    x[0] = x0
    for t in range(1, T):
        x[t] = F @ x[t - 1] + B[:, 0] * sigma_w * rng.normal()
    return x[:, 0] + sigma_v * rng.normal(size=T)


def assert_close_rel(a: np.ndarray, b: np.ndarray, tol: float) -> None:
    """|a − b| <= tol · max(1, |b|) elementwise (absolute for small values, relative for large)."""
    assert np.all(np.abs(a - b) <= tol * np.maximum(1.0, np.abs(b))), np.max(np.abs(a - b) / np.maximum(1, np.abs(b)))


@pytest.fixture(scope="module")
def track() -> np.ndarray:
    y = simulate(np.random.default_rng(1), 150)
    y[[0, 10, 50, 51, 52, 53, 90, 149]] = np.nan  # missing first frame, single gaps, a burst, missing last frame
    return y


@pytest.mark.parametrize("N", [2, 3, 5, 20, 60, 200])
def test_kernel_form_equals_iterative_alg4(track: np.ndarray, N: int) -> None:
    """Every frame (start-up, NaN windows, unobservable frames, full windows) against Alg. 4 run literally."""
    fast = filters.make("oufir", filters.constant_velocity(TAU), sigma_w=50.0, sigma_v=4.0, horizon=N).run(
        track[:, None])
    ref = oufir_iterative(track, F, H, B, N, 50.0, 4.0)
    assert np.isnan(ref[0]).all() and np.isnan(fast[0]).all()  # nothing seen yet at frame 0
    assert_close_rel(fast[1:], ref[1:], 1e-8)


def test_gain_is_unbiased_and_zero_at_missing_samples() -> None:
    valid = np.ones(30, bool)
    valid[[3, 4, 17]] = False
    W = oufir_gain(F, H, B, valid, 50.0, 4.0)
    C_f = np.stack([H[0] @ np.linalg.matrix_power(F, i) for i in range(30)])
    np.testing.assert_allclose(W @ C_f, np.linalg.matrix_power(F, 29), atol=1e-11)  # K C_f = F^{N−1} (§1.6)
    assert np.all(W[:, ~valid] == 0)


def test_noiseless_ramp_reproduced_exactly_with_gaps() -> None:
    t = np.arange(80) * TAU
    y = 3.0 + 7.0 * t
    y[[5, 30, 31, 32]] = np.nan
    out = filters.make("oufir", filters.constant_velocity(TAU), sigma_w=10.0, sigma_v=1.0, horizon=25).run(y[:, None])
    np.testing.assert_allclose(out[1:, 0], 3.0 + 7.0 * t[1:], atol=1e-9)
    np.testing.assert_allclose(out[1:, 1], 7.0, atol=1e-7)


def test_cholesky_and_ml_least_squares_branches_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    valid = np.ones(60, bool)
    valid[[0, 7, 30]] = False
    P_prior = np.diag([1.0, 400.0])
    chol = [window_gls_gain(F, H, B, valid, r, P) for r in (0.1, 12.5) for P in (None, P_prior)]
    monkeypatch.setattr(oufir, "COND_MAX", 0.0)
    ml = [window_gls_gain(F, H, B, valid, r, P) for r in (0.1, 12.5) for P in (None, P_prior)]
    for (Wy_c, Wx_c), (Wy_m, Wx_m) in zip(chol, ml, strict=False):
        np.testing.assert_allclose(Wy_c, Wy_m, atol=1e-10 * np.abs(Wy_c).max())
        np.testing.assert_allclose(Wx_c, Wx_m, atol=1e-10 * max(np.abs(Wx_c).max(), 1.0))


@pytest.mark.parametrize("ratio", [1e4, 1e8, 1e12])
def test_ill_conditioned_gain_is_finite_and_unbiased(ratio: float) -> None:
    """σ_w/σ_v huge over a long window: Ψ_Y has no usable Cholesky factor; the ML branch still gives the
    unbiased gain, and it equals the Kalman recursion of the start-up path (T < N) to 1e-9 relative."""
    W = oufir_gain(F, H, B, np.ones(400, bool), ratio, 1.0)
    assert np.all(np.isfinite(W))
    C_f = np.stack([H[0] @ np.linalg.matrix_power(F, i) for i in range(400)])
    np.testing.assert_allclose(W @ C_f, np.linalg.matrix_power(F, 399), atol=1e-6 * np.abs(W).max())
    y = simulate(np.random.default_rng(8), 400)
    out = filters.make("oufir", filters.constant_velocity(TAU), sigma_w=ratio, sigma_v=1.0, horizon=401).run(y[:, None])
    np.testing.assert_allclose(out[-1], W @ y, rtol=1e-9)


@pytest.mark.parametrize("name", ["oufir", "fir"])
def test_recursive_frames_equal_batch_gains(name: str) -> None:
    """Start-up frames (growing window) and windows holding a NaN are computed by the Kalman recursion on the
    data; each must equal the batch gain of its window (missing samples dropped) applied to the data."""
    y = simulate(np.random.default_rng(9), 70)
    y[[0, 3, 4, 40, 66]] = np.nan
    N = 30
    out = filters.make(name, filters.constant_velocity(TAU), sigma_w=20.0, sigma_v=3.0, horizon=N).run(y[:, None])
    valid = np.isfinite(y)
    y0 = np.where(valid, y, 0.0)
    for n in range(2, 70):
        m = max(0, n - N + 1)
        W = oufir_gain(F, H, B, valid[m: n + 1], 20.0, 3.0)
        np.testing.assert_allclose(out[n], W @ y0[m: n + 1], rtol=1e-10, atol=1e-9)


def steady_state_kf(sigma_w: float, sigma_v: float) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state KF gain K_ss (2,) and closed-loop matrix (I − K_ss H) F."""
    P = sla.solve_discrete_are(F.T, H.T, sigma_w**2 * B @ B.T, np.array([[sigma_v**2]]))
    K = (P @ H.T / (H @ P @ H.T + sigma_v**2))[:, 0]
    return K, (np.eye(2) - np.outer(K, H[0])) @ F


def test_long_horizon_gain_converges_to_steady_state_kf() -> None:
    """Notes §3 table: the OUFIR kernel at N = 160 equals the steady-state KF impulse response
    [((I − KH)F)^k K_ss] truncated to N taps. Measured: 3.8e-9 (all taps), 1e-12 (newest tap)."""
    K, A = steady_state_kf(50.0, 4.0)
    W = oufir_gain(F, H, B, np.ones(160, bool), 50.0, 4.0)
    W_kf = np.stack([np.linalg.matrix_power(A, k) @ K for k in range(160)][::-1], axis=1)
    assert np.abs(W - W_kf).max() < 1e-8
    assert np.abs(W[:, -1] - K).max() < 1e-11
    W20 = oufir_gain(F, H, B, np.ones(20, bool), 50.0, 4.0)
    assert np.abs(W20[:, -1] - K).max() > 1e-3  # a short horizon is not yet the KF


def test_long_horizon_run_converges_to_kf_run() -> None:
    """Same data through a KF (started at frame 0) and OUFIR N = 160: after the KF's transient the
    estimates agree to 1.2e-7 (notes §3: 9e-8); at N = 40 they still differ by ~0.4."""
    y = simulate(np.random.default_rng(5), 1200)
    Q, R = 50.0**2 * B @ B.T, 16.0
    x, P = np.array([y[0], 0.0]), np.diag([R, 1e6])
    kf = [x]
    for t in range(1, y.size):
        x, P = kf_step(x, P, y[t], F, H, Q, R)
        kf.append(x)
    kf = np.array(kf)
    model = filters.constant_velocity(TAU)
    for N, lo, hi in ((160, 0.0, 1e-6), (40, 0.05, np.inf)):
        out = filters.make("oufir", model, sigma_w=50.0, sigma_v=4.0, horizon=N).run(y[:, None])
        assert lo < np.abs(out[400:] - kf[400:]).max() < hi


@pytest.mark.parametrize("name", ["oufir", "fir", "ofir"])
def test_batched_and_per_track_parameters_equal_separate_runs(name: str) -> None:
    rng = np.random.default_rng(3)
    model = filters.constant_velocity(TAU, ndim=2)
    y = np.stack([np.stack([simulate(rng, 70), simulate(rng, 70)], axis=1) for _ in range(3)])
    y[1, 20:23, 0] = np.nan
    sw, sv, N = np.array([50.0, 5.0, 50.0]), np.array([4.0, 1.0, 4.0]), np.array([20, 7, 33])
    batched = filters.make(name, model, sigma_w=sw, sigma_v=sv, horizon=N).run(y)
    for b in range(3):
        single = filters.make(name, model, sigma_w=sw[b], sigma_v=sv[b], horizon=int(N[b])).run(y[b])
        np.testing.assert_allclose(batched[b], single, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("name", ["oufir", "fir", "ofir"])
@settings(max_examples=25, deadline=None)
@given(sigma_w=st.floats(1e-6, 1e6), sigma_v=st.floats(1e-6, 1e6),
       N=st.one_of(st.integers(2, 12), st.integers(2, 10_000)),
       T=st.integers(1, 12), seed=st.integers(0, 2**16), drop=st.floats(0.0, 0.5))
def test_finite_input_gives_finite_output(name: str, sigma_w: float, sigma_v: float, N: int, T: int, seed: int,
                                          drop: float) -> None:
    rng = np.random.default_rng(seed)
    y = rng.normal(size=(2, T, 1)) * 100 + 300
    y[:, 1:][rng.random((2, T - 1, 1)) < drop] = np.nan  # frame 0 stays valid, so every output is defined
    out = filters.make(name, filters.constant_velocity(TAU), sigma_w=sigma_w, sigma_v=sigma_v,
                       horizon=N).run(y)
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize("params, name", [
    ({"horizon": 1}, "horizon"), ({"horizon": 2.5}, "horizon"), ({"sigma_w": 0.0}, "sigma_w"),
    ({"sigma_v": np.inf}, "sigma_v"), ({"sigma_v": -1.0}, "sigma_v"), ({"sigma_w": np.nan}, "sigma_w"),
    ({"sigma_w": np.ones(2), "sigma_v": np.ones(3)}, "length"), ({"psi": 0.5}, "psi"),
])
def test_bad_parameters_raise_value_error_naming_them(params: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        filters.make("oufir", filters.constant_velocity(TAU), **params)


def test_per_track_array_must_match_batch() -> None:
    f = filters.make("oufir", filters.constant_velocity(TAU), sigma_w=np.ones(3))
    with pytest.raises(ValueError, match="sigma_w"):
        f.run(np.zeros((2, 10, 1)))
