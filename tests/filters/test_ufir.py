"""UFIR (filters/ufir.py): fast kernel form vs the literal iterative Algorithm, least-squares line oracle,
unbiasedness, closed-form ramp gain, batching and per-track parameters, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters.horizon import rule_horizon
from bboxtune.filters.lag_moments import lag_moments, lag_moments_real, lag_polynomial
from bboxtune.filters.ufir import UFIR, back_projected_rows, ramp_gain, ufir_iterative

TAU = 0.05
MODEL1 = filters.constant_velocity(TAU, ndim=1)
AXIS = MODEL1.axis()


def track(T: int, seed: int = 0, sigma_v: float = 4.0) -> np.ndarray:
    """One noisy constant-velocity coordinate (T,) around a few hundred units."""
    rng = np.random.default_rng(seed)
    velocity = 20.0 + np.cumsum(rng.normal(0.0, 50.0 * TAU, T))
    return 300.0 + np.cumsum(velocity) * TAU + rng.normal(0.0, sigma_v, T)


def assert_close(fast: np.ndarray, ref: np.ndarray, rtol: float = 1e-8) -> None:
    """Equal to rtol relative to each state component's largest magnitude (NaN where the other is NaN)."""
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(ref))
    scale = np.maximum(np.nanmax(np.abs(ref), axis=0), 1.0)
    worst = np.nanmax(np.abs(fast - ref), axis=0, initial=0.0) / scale
    assert np.all(worst < rtol), f"relative difference {worst} >= {rtol}"


def run1(y: np.ndarray, **params) -> np.ndarray:
    return filters.make("ufir", MODEL1, **params).run(y[:, None])


@pytest.mark.parametrize("N", [2, 3, 10, 37])
def test_fast_equals_iterative_every_frame(N: int) -> None:
    y = track(90, seed=N)
    assert_close(run1(y, horizon=N), ufir_iterative(y, AXIS.F, AXIS.H, N))


@pytest.mark.parametrize("N", [2, 5, 25])
def test_fast_equals_iterative_with_missing(N: int) -> None:
    y = track(80, seed=1)
    y[[0, 1, 7, 30, 31, 32, 33, 60]] = np.nan  # leading gap, single gaps and a run
    y[40:40 + N + 3] = np.nan  # a gap longer than the horizon (unobservable windows)
    fast = run1(y, horizon=N)
    assert_close(fast, ufir_iterative(y, AXIS.F, AXIS.H, N))
    assert np.all(np.isnan(fast[:2])) and np.all(np.isfinite(fast[2:]))  # NaN only before the first sample


def test_position_and_velocity_are_the_least_squares_line() -> None:
    N, y = 12, track(60, seed=2)
    out = run1(y, horizon=N)
    for n in range(1, 60):
        m = max(0, n - N + 1)
        t = (np.arange(m, n + 1) - n) * TAU
        slope, intercept = np.polyfit(t, y[m:n + 1], 1)  # straight line over the horizon (start-up: all so far)
        np.testing.assert_allclose(out[n], [intercept, slope], rtol=1e-10, atol=1e-9)


def test_first_frame_holds_the_measurement() -> None:
    out = run1(np.array([5.0, 7.0, 9.0]), horizon=3)
    np.testing.assert_allclose(out[0], [5.0, 0.0])
    np.testing.assert_allclose(out[2], [9.0, 2.0 / TAU])


@pytest.mark.parametrize("degree", [0, 1])
def test_noiseless_polynomials_of_degree_below_K_are_reproduced(degree: int) -> None:
    t = np.arange(200) * TAU
    p = 50.0 + 3.0 * t if degree else np.full(200, 50.0)
    out = run1(p, horizon=40)
    np.testing.assert_allclose(out[1:, 0], p[1:], rtol=1e-12)
    np.testing.assert_allclose(out[1:, 1], 3.0 * degree, atol=1e-8)


@pytest.mark.parametrize("N", [2, 3, 8, 20, 160])
def test_closed_form_ramp_gain_equals_batch_formula(N: int) -> None:
    f = UFIR(MODEL1, horizon=N)
    W = f.window_gain(np.ones(N, bool), {"horizon": N})
    np.testing.assert_allclose(W, ramp_gain(N, TAU), rtol=1e-9, atol=1e-12)
    C = back_projected_rows(AXIS.F, AXIS.H, N)
    np.testing.assert_allclose(W @ C, np.eye(2), atol=1e-9)  # unbiasedness K C̄ = I
    np.testing.assert_allclose(np.sum(W[0] ** 2), 2 * (2 * N - 1) / (N * (N + 1)), rtol=1e-12)  # NPG, notes §1.1


def test_masked_gain_is_zero_at_missing_samples_and_unbiased() -> None:
    valid = np.array([True, False, True, True, False, True])
    W = UFIR(MODEL1, horizon=6).window_gain(valid, {"horizon": 6})
    assert np.all(W[:, ~valid] == 0.0)
    np.testing.assert_allclose(W @ back_projected_rows(AXIS.F, AXIS.H, 6), np.eye(2), atol=1e-10)


def test_batched_equals_one_track_at_a_time_and_per_track_horizons() -> None:
    model = filters.constant_velocity(TAU, ndim=4)
    rng = np.random.default_rng(3)
    Y = np.stack([np.stack([track(70, seed=4 * b + j) for j in range(4)], axis=1) for b in range(5)])
    Y[rng.uniform(size=Y.shape) < 0.08] = np.nan
    horizons = np.array([2, 9, 9, 30, 100])
    batched = filters.make("ufir", model, horizon=horizons).run(Y)
    assert batched.shape == (5, 70, 8)
    for b in range(5):
        single = filters.make("ufir", model, horizon=int(horizons[b])).run(Y[b])
        np.testing.assert_allclose(batched[b], single, rtol=1e-12, atol=1e-10)
        for j in range(4):  # coordinates are independent one-coordinate channels, positions then velocities
            ref = ufir_iterative(Y[b, :, j], AXIS.F, AXIS.H, int(horizons[b]))
            assert_close(batched[b][:, [j, 4 + j]], ref)


def test_default_horizon_follows_the_rule_per_track() -> None:
    sigma_w = np.array([50.0, 5.0])
    f = filters.make("ufir", MODEL1, sigma_w=sigma_w, sigma_v=4.0)
    np.testing.assert_array_equal(f.params["horizon"], rule_horizon(4.0, sigma_w, TAU, 2))
    y = np.stack([track(50, seed=5), track(50, seed=6)])[:, :, None]
    out = f.run(y)
    for b, N in enumerate(f.params["horizon"]):
        assert_close(out[b], ufir_iterative(y[b, :, 0], AXIS.F, AXIS.H, int(N)))


def test_state_of_other_tau_is_not_served_from_the_cache() -> None:
    y = track(40, seed=7)
    for tau in (0.05, 1.0):
        model = filters.constant_velocity(tau, ndim=1)
        out = filters.make("ufir", model, horizon=10).run(y[:, None])
        assert_close(out, ufir_iterative(y, model.F, model.H, 10))


@settings(max_examples=25, deadline=None)
@given(
    sigma_w=st.floats(1e-6, 1e6),
    sigma_v=st.floats(1e-6, 1e6),
    N=st.one_of(st.none(), st.integers(2, 10_000)),
    T=st.integers(1, 25),
    scale=st.floats(1e-3, 1e6),
    seed=st.integers(0, 2**16),
)
def test_finite_input_gives_finite_output(sigma_w, sigma_v, N, T, scale, seed) -> None:
    y = np.random.default_rng(seed).normal(0.0, scale, (2, T, 1))
    out = filters.make("ufir", MODEL1, sigma_w=sigma_w, sigma_v=sigma_v, horizon=N).run(y)
    assert out.shape == (2, T, 2) and np.all(np.isfinite(out))


@pytest.mark.parametrize(
    "params, name",
    [
        ({"horizon": 1}, "horizon"),
        ({"horizon": 2.5}, "horizon"),
        ({"horizon": -3}, "horizon"),
        ({"horizon": np.inf}, "horizon"),
        ({"sigma_w": 0.0}, "sigma_w"),
        ({"sigma_v": -1.0}, "sigma_v"),
        ({"sigma_v": np.nan}, "sigma_v"),
        ({"horizon": np.array([5, 6]), "sigma_w": np.array([1.0, 2.0, 3.0])}, "lengths"),
        ({"psi": 0.5}, "psi"),
    ],
)
def test_bad_parameters_raise_naming_them(params, name) -> None:
    with pytest.raises(ValueError, match=name):
        filters.make("ufir", MODEL1, **params)


def test_per_track_array_must_match_batch() -> None:
    f = filters.make("ufir", MODEL1, horizon=np.array([3, 4, 5]))
    with pytest.raises(ValueError, match="horizon"):
        f.run(np.zeros((2, 10, 1)))


def test_iterative_reference_on_the_full_box_model_equals_fast() -> None:
    model = filters.constant_velocity(TAU, ndim=4)
    y = np.stack([track(45, seed=10 + j) for j in range(4)], axis=1)
    y[[4, 20, 21]] = np.nan  # whole boxes missing
    assert_close(filters.make("ufir", model, horizon=9).run(y), ufir_iterative(y, model.F, model.H, 9))


@pytest.mark.parametrize("N", [1, 2, 7, 40])
def test_lag_moments_equal_direct_window_sums(N: int) -> None:
    rng = np.random.default_rng(N)
    s = np.stack([rng.normal(300.0, 5.0, (3, 30)), (rng.random((3, 30)) < 0.3).astype(float)])  # (2, 3, 30)
    k = np.arange(N)
    window = np.arange(30)[:, None] - k  # frames n − k, (T, N)
    taps = np.where(window >= 0, s[..., np.maximum(window, 0)], 0.0)  # (2, 3, T, N)
    direct = np.stack([taps @ k.astype(float) ** p for p in range(3)])
    np.testing.assert_allclose(lag_moments_real(s[0], N), direct[:2, 0], rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(lag_moments(s[1], N, 3), direct[:, 1])  # 0/1 signals: exact integers


def test_lag_moments_of_a_long_track_keep_the_precision_of_one_window() -> None:
    rng = np.random.default_rng(5)
    T, N = 200_000, 60
    s = rng.normal(1e4, 5.0, T)
    got = lag_moments_real(s, N)[:, -5:]
    whole = [N, N * (N - 1) / 2, (N - 1) * N * (2 * N - 1) / 6]  # Σ_{k<N} k^p
    np.testing.assert_array_equal(lag_moments(np.ones(T), N, 3)[:, -1], whole)  # exact after 200,000 frames
    k = np.arange(N, dtype=float)
    direct = [[s[n - N + 1: n + 1][::-1] @ k**p for n in range(T - 5, T)] for p in range(2)]
    np.testing.assert_allclose(got, direct, rtol=1e-12)


def test_lag_polynomial_is_the_constant_velocity_back_projection() -> None:
    c0, c1 = lag_polynomial(AXIS.F, AXIS.H)
    rows = back_projected_rows(AXIS.F, AXIS.H, 12)[::-1]  # H F^{−k}, k = 0 … 11
    np.testing.assert_allclose(c0 + np.arange(12)[:, None] * c1, rows, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="constant-velocity"):
        lag_polynomial(np.array([[1.0, 0.1], [0.0, 0.9]]), AXIS.H)


@pytest.mark.parametrize("psi", [0.0, 0.6])
def test_windows_with_gaps_late_in_a_long_track_equal_the_iterative_reference(psi: float) -> None:
    """The NaN windows are corrections of the clean kernel by lag moments over the whole track: check the last
    windows of a long track (values ~1e4) against Algorithm 2 run on their frames only."""
    rng = np.random.default_rng(8)
    T, N = 40_000, 25
    y = 1e4 + track(T, seed=8)
    y[rng.random(T) < 0.05] = np.nan
    fast = filters.make("ufir_cmn", MODEL1, psi=psi, horizon=N).run(y[:, None])
    tail = y[-200:]
    ref = ufir_iterative(tail, AXIS.F, AXIS.H, N, psi)
    assert_close(fast[-200 + N + 1:], ref[N + 1:], rtol=1e-9)
