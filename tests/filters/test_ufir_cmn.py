"""UFIR-CMN (filters/ufir_cmn.py): fast form vs literal Algorithm 2 ([Shmaliy-CMN]), ψ = 0 is UFIR, differencing
folded into the raw-window gain, unbiasedness, per-track ψ, rank-deficient windows, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters.ufir import back_projected_rows, ufir_iterative
from bboxtune.filters.ufir_cmn import UFIRCMN
from tests.filters.test_ufir import assert_close

TAU = 0.05
MODEL1 = filters.constant_velocity(TAU, ndim=1)
AXIS = MODEL1.axis()


def cmn_track(T: int, psi: float, seed: int = 0) -> np.ndarray:
    """CV coordinate with Gauss–Markov measurement noise v_l = ψ v_{l−1} + ξ_l (σ_ξ = 4)."""
    rng = np.random.default_rng(seed)
    velocity = 20.0 + np.cumsum(rng.normal(0.0, 50.0 * TAU, T))
    v = np.zeros(T)
    for l in range(1, T):
        v[l] = psi * v[l - 1] + rng.normal(0.0, 4.0)
    return 300.0 + np.cumsum(velocity) * TAU + v


def run1(y: np.ndarray, **params) -> np.ndarray:
    return filters.make("ufir_cmn", MODEL1, **params).run(y[:, None])


@pytest.mark.parametrize("psi", [0.3, 0.6, 0.9])
@pytest.mark.parametrize("N", [2, 5, 30])
def test_fast_equals_algorithm_2_every_frame(psi: float, N: int) -> None:
    y = cmn_track(80, psi, seed=N)
    assert_close(run1(y, psi=psi, horizon=N), ufir_iterative(y, AXIS.F, AXIS.H, N, psi))


@pytest.mark.parametrize("psi", [0.0, 0.5, 0.95])
@pytest.mark.parametrize("N", [2, 4, 20])
def test_fast_equals_algorithm_2_with_missing(psi: float, N: int) -> None:
    y = cmn_track(90, psi, seed=1)
    y[[0, 6, 20, 21, 50, 52, 54]] = np.nan  # a NaN at frame 0, single gaps, a pair, alternating gaps
    y[65:65 + N + 2] = np.nan  # longer than the horizon
    assert_close(run1(y, psi=psi, horizon=N), ufir_iterative(y, AXIS.F, AXIS.H, N, psi), rtol=1e-7)


def test_psi_zero_is_ufir_on_every_frame_including_gaps() -> None:
    y = cmn_track(70, 0.0, seed=2)
    y[[3, 4, 30, 44]] = np.nan
    for N in (2, 7, 25):
        cmn = run1(y, psi=0.0, horizon=N)
        ufir = filters.make("ufir", MODEL1, horizon=N).run(y[:, None])
        np.testing.assert_allclose(cmn, ufir, rtol=1e-10, atol=1e-9)


def test_full_window_gain_is_least_squares_on_differenced_samples() -> None:
    N, psi = 8, 0.7
    y = cmn_track(N + 1, psi, seed=3)
    W = UFIRCMN(MODEL1, psi=psi, horizon=N).window_gain(np.ones(N + 1, bool), {"psi": psi, "horizon": N})
    assert W.shape == (2, N + 1)
    z = y[1:] - psi * y[:-1]  # [Shmaliy-CMN] eq. 4
    D = AXIS.H - psi * AXIS.H @ np.linalg.inv(AXIS.F)
    np.testing.assert_allclose(D, [[1 - psi, psi * TAU]])  # notes §1.3: D = [1 − ψ, ψτ]
    C = back_projected_rows(AXIS.F, D, N)  # rows D F^{−(N−1−i)}
    np.testing.assert_allclose(W @ y, np.linalg.lstsq(C, z, rcond=None)[0], rtol=1e-10)


def test_padded_batch_of_full_gains_equals_each_window_alone() -> None:
    f = filters.make("ufir_cmn", MODEL1, psi=0.5, horizon=10)
    psi, horizon = np.array([0.0, 0.4, 0.93, 0.7]), np.array([2, 9, 40, 40])
    batch = f.clean_gains({"psi": psi, "horizon": horizon}, 41)
    for p, N, W in zip(psi, horizon, batch, strict=False):
        alone = f.window_gains(np.ones((1, N + 1), bool), {"psi": np.array([p]), "horizon": np.array([N])})[0]
        np.testing.assert_allclose(W[:, 41 - (N + 1):], alone, rtol=1e-11, atol=1e-12 * np.abs(alone).max())
        assert not W[:, : 41 - (N + 1)].any()  # zero before a shorter window


@pytest.mark.parametrize("psi", [0.0, 0.5, 0.99])
def test_noiseless_ramp_is_reproduced(psi: float) -> None:
    p = 40.0 + 6.0 * np.arange(150) * TAU
    out = run1(p, psi=psi, horizon=60)
    np.testing.assert_allclose(out[1:, 0], p[1:], rtol=1e-9)
    np.testing.assert_allclose(out[1:, 1], 6.0, rtol=1e-6)


def test_per_track_psi_and_horizon_equal_separate_runs() -> None:
    model = filters.constant_velocity(TAU, ndim=2)
    psi = np.array([0.0, 0.6, 0.6, 0.9])
    horizon = np.array([5, 5, 31, 100])
    Y = np.stack([np.stack([cmn_track(60, p, seed=2 * b + j) for j in range(2)], axis=1) for b, p in enumerate(psi)])
    Y[1, 10, 0] = Y[3, 30:33, 1] = np.nan
    batched = filters.make("ufir_cmn", model, psi=psi, horizon=horizon).run(Y)
    for b in range(4):
        single = filters.make("ufir_cmn", model, psi=float(psi[b]), horizon=int(horizon[b])).run(Y[b])
        np.testing.assert_allclose(batched[b], single, rtol=1e-12, atol=1e-10)


def test_rank_deficient_window_falls_back_to_the_latest_measurement() -> None:
    # ψ = 2/3, N = 3: the window y_1, y_2, (y_3 missing), y_4 keeps a differenced row z_2 and an undifferenced
    # y_4 (predecessor missing) whose back-projected rows are parallel → the state is not determined.
    psi, N = 2.0 / 3.0, 3
    y = np.array([1.0, 2.0, 4.0, np.nan, 9.0, 11.0])
    fast = run1(y, psi=psi, horizon=N)
    np.testing.assert_allclose(fast[4], [9.0, 0.0])
    assert not UFIRCMN(MODEL1, psi=psi, horizon=N).observable(
        np.array([[True, True, False, True]]), {"psi": np.array([psi]), "horizon": np.array([N])})[0]
    assert_close(fast, ufir_iterative(y, AXIS.F, AXIS.H, N, psi))


@settings(max_examples=25, deadline=None)
@given(
    psi=st.floats(0.0, 0.99),  # bboxtune.filters.validation.PSI_MAX
    sigma_w=st.floats(1e-6, 1e6),
    sigma_v=st.floats(1e-6, 1e6),
    N=st.one_of(st.none(), st.integers(2, 10_000)),
    T=st.integers(1, 25),
    gap=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_finite_input_gives_finite_output(psi, sigma_w, sigma_v, N, T, gap, seed) -> None:
    y = np.random.default_rng(seed).normal(0.0, 100.0, (2, T, 1))
    if gap and T > 1:  # frame 0 stays finite: output is never NaN then
        y[:, T // 2] = np.nan
    out = filters.make("ufir_cmn", MODEL1, psi=psi, sigma_w=sigma_w, sigma_v=sigma_v, horizon=N).run(y)
    assert out.shape == (2, T, 2) and np.all(np.isfinite(out))


@pytest.mark.parametrize("psi", [-0.1, 1.0, 1.5, np.nan, np.array([0.2, 1.0])])
def test_bad_psi_raises_naming_it(psi) -> None:
    with pytest.raises(ValueError, match="psi"):
        filters.make("ufir_cmn", MODEL1, psi=psi)


def test_mismatched_per_track_arrays_raise() -> None:
    with pytest.raises(ValueError, match="lengths"):
        filters.make("ufir_cmn", MODEL1, psi=np.array([0.1, 0.2]), horizon=np.array([3, 4, 5]))
