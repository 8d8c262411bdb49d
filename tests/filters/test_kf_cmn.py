"""KF-CMN back end ([Shmaliy-CMN] Algorithm 1): ψ = 0 is the KF, agreement with the time-correlated form
(filterpy ``update_correlated``, across gaps with the gap-spanning difference of docs/notes/kf-cmn-gaps.md) and with
the notes' alternative de-correlated form, batching, bad input. More on gaps: tests/filters/test_cmn_gaps.py."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from tests.filters.test_kf import assert_rel, simulate

TAU = 0.05
AXIS = filters.constant_velocity(TAU).axis()
X0, P0 = np.array([100.0, 20.0]), np.diag([10.0, 100.0])


def simulate_cmn(rng: np.random.Generator, T: int, sigma_w: float, sigma_v: float,
                 psi: float) -> tuple[np.ndarray, np.ndarray]:
    """Track (T,) and measurements (T,) with Gauss–Markov noise v_n = ψ v_{n-1} + ξ_n (stationary start)."""
    truth = simulate(rng, T, 1, sigma_w, 0.0)[:, 0]
    xi = rng.normal(size=T) * sigma_v
    v = np.empty(T)
    v[0] = xi[0] / np.sqrt(1 - psi**2)
    for n in range(1, T):
        v[n] = psi * v[n - 1] + xi[n]
    return truth, truth + v


def cmn_matrices(sigma_w: float, sigma_v: float, psi: float, gap: int = 0) -> dict[str, np.ndarray]:
    """The time-correlated model of z_n = y_n − ψ^{g+1} y_m, g = ``gap`` frames missing between, by explicit sums:
    x_n = F^{g+1} x_m + w_g, Q_g = Σ_{j<=g} F^j Q F^jᵀ, Γ = ψ^{g+1} H F^{−(g+1)}, v̄ = Γ w_g + Σ_{k<=g} ψ^k ξ_{n−k}."""
    F, H = AXIS.F, AXIS.H
    Q = sigma_w**2 * AXIS.B @ AXIS.B.T
    Q_g = sum(np.linalg.matrix_power(F, j) @ Q @ np.linalg.matrix_power(F, j).T for j in range(gap + 1))
    Gamma = psi ** (gap + 1) * H @ np.linalg.inv(np.linalg.matrix_power(F, gap + 1))
    var_e = sigma_v**2 * sum(psi ** (2 * k) for k in range(gap + 1))
    M = Q_g @ Gamma.T  # E{w_g v̄_nᵀ}
    return {"F": F, "H": H, "Q": Q, "D": H - Gamma, "M": M, "R_bar": Gamma @ Q_g @ Gamma.T + var_e}


def time_correlated(y: np.ndarray, sigma_w: float, sigma_v: float, psi: float, x0: np.ndarray = X0,
                    P0: np.ndarray = P0) -> np.ndarray:
    """filterpy: the first finite y a standard update with var(v) = σ²/(1−ψ²); every later finite y_n
    update_correlated on z_n = y_n − ψ^{g+1} y_m, y_m the last finite y, g frames missing between (H = D, R = R̄,
    M = Q_g Γᵀ of :func:`cmn_matrices`); predict-only where y_n is missing."""
    kf = KalmanFilter(dim_x=2, dim_z=1)
    m = cmn_matrices(sigma_w, sigma_v, psi)
    kf.F, kf.Q = m["F"], m["Q"]
    kf.x, kf.P = x0.copy(), P0.copy()
    out, last = [], None
    for n in range(len(y)):
        kf.predict()
        if np.isnan(y[n]):
            kf.update(None)
        elif last is None:
            kf.update(y[n], R=np.eye(1) * sigma_v**2 / (1 - psi**2), H=m["H"])
        else:
            g = n - last - 1
            step = cmn_matrices(sigma_w, sigma_v, psi, g)
            kf.M = step["M"]
            kf.update_correlated(np.array([y[n] - psi ** (g + 1) * y[last]]), R=step["R_bar"], H=step["D"])
        last = last if np.isnan(y[n]) else n
        out.append(kf.x.copy())
    return np.array(out)


def decorrelated_notes_form(y: np.ndarray, sigma_w: float, sigma_v: float, psi: float) -> np.ndarray:
    """Notes §1.4 de-correlated form: Λ' = M R̄⁻¹, A' = (I + Λ'D)⁻¹, Q̃ = Q − M R̄⁻¹ Mᵀ (no missing data)."""
    m = cmn_matrices(sigma_w, sigma_v, psi)
    F, D, R_bar = m["F"], m["D"], m["R_bar"]
    Lam = m["M"] @ np.linalg.inv(R_bar)
    A = np.linalg.inv(np.eye(2) + Lam @ D)
    Q_tilde = m["Q"] - Lam @ m["M"].T
    x, P = F @ X0, F @ P0 @ F.T + m["Q"]  # frame 0: standard update on y_0
    S = P[0, 0] + sigma_v**2 / (1 - psi**2)
    K = P[:, 0] / S
    x, P = x + K * (y[0] - x[0]), P - np.outer(K, K) * S
    out = [x]
    for n in range(1, len(y)):
        z = y[n] - psi * y[n - 1]
        x = A @ (F @ x + Lam[:, 0] * z)
        P = A @ (F @ P @ F.T + Q_tilde) @ A.T
        S = D @ P @ D.T + R_bar
        K = (P @ D.T / S)[:, 0]
        x = x + K * (z - D @ x)
        P = P - np.outer(K, K) * S
        out.append(x)
    return np.array(out)


@pytest.mark.parametrize("psi", [0.3, 0.8, 0.95])
def test_equals_time_correlated_and_notes_decorrelated_form(psi: float) -> None:
    rng = np.random.default_rng(int(psi * 100))
    _, y = simulate_cmn(rng, 1500, 50.0, 4.0, psi)
    ours = filters.make("kf_cmn", filters.constant_velocity(TAU), sigma_w=50.0, sigma_v=4.0, psi=psi,
                        x0=X0, P0=P0).run(y[:, None])
    assert_rel(ours, time_correlated(y, 50.0, 4.0, psi), 1e-12)
    assert_rel(ours, decorrelated_notes_form(y, 50.0, 4.0, psi), 1e-10)


def test_missing_data_matches_time_correlated_form() -> None:
    rng = np.random.default_rng(7)
    _, y = simulate_cmn(rng, 600, 30.0, 3.0, 0.7)
    y[[0, 4, 5, 6, 100, 300, 301]] = np.nan
    ours = filters.make("kf_cmn", filters.constant_velocity(TAU), sigma_w=30.0, sigma_v=3.0, psi=0.7,
                        x0=X0, P0=P0).run(y[:, None])
    assert_rel(ours, time_correlated(y, 30.0, 3.0, 0.7), 1e-12)


def test_psi_zero_is_bit_identical_to_kf() -> None:
    rng = np.random.default_rng(8)
    model = filters.constant_velocity(TAU, ndim=4)
    y = simulate(rng, 500, 4, 20.0, 2.0, B=3)
    y[1, :3] = np.nan  # late start (no prior)
    y[0, 40:47] = y[2, 100:101, 2] = y[1, 300:330, 1:3] = np.nan  # gaps: the first y after each is used
    sw, sv = np.array([1.0, 20.0, 300.0]), np.array([2.0, 0.3, 5.0])
    kf = filters.make("kf", model, sigma_w=sw, sigma_v=sv).run(y)
    cmn = filters.make("kf_cmn", model, sigma_w=sw, sigma_v=sv, psi=0.0).run(y)
    np.testing.assert_array_equal(cmn, kf)
    x0 = np.r_[np.full(4, 100.0), np.zeros(4)]
    prior = {"x0": x0, "P0": np.eye(8) * 50.0}
    np.testing.assert_array_equal(filters.make("kf_cmn", model, psi=0.0, **prior).run(y[0]),
                                  filters.make("kf", model, **prior).run(y[0]))


def test_lower_error_than_kf_on_coloured_noise() -> None:
    """ψ = 0.8: KF-CMN beats a KF that models the noise as white with the same stationary variance
    (notes §4: 5.3 vs 5.8 px analytic/MC)."""
    rng = np.random.default_rng(9)
    truth, y = simulate_cmn(rng, 4000, 50.0, 4.0, 0.8)
    model = filters.constant_velocity(TAU)
    cmn = filters.make("kf_cmn", model, sigma_w=50.0, sigma_v=4.0, psi=0.8).run(y[:, None])[100:, 0]
    white = filters.make("kf", model, sigma_w=50.0, sigma_v=4.0 / np.sqrt(1 - 0.64)).run(y[:, None])[100:, 0]
    rmse_cmn = np.sqrt(np.mean((cmn - truth[100:]) ** 2))
    rmse_white = np.sqrt(np.mean((white - truth[100:]) ** 2))
    assert rmse_cmn < 0.97 * rmse_white


def test_batched_equals_separate_runs() -> None:
    rng = np.random.default_rng(10)
    model = filters.constant_velocity(TAU, ndim=2)
    y = simulate(rng, 300, 2, 10.0, 2.0, B=4)
    y[2, 40:45, 1] = np.nan
    params = {"sigma_w": np.array([1.0, 10.0, 10.0, 80.0]), "sigma_v": np.array([2.0, 2.0, 1.0, 3.0]),
              "psi": np.array([0.0, 0.5, 0.9, 0.99])}
    batched = filters.make("kf_cmn", model, **params).run(y)
    for b in range(4):
        single = filters.make("kf_cmn", model, **{k: v[b] for k, v in params.items()}).run(y[b])
        np.testing.assert_allclose(batched[b], single, rtol=1e-12, atol=1e-9)
        assert np.all(np.isfinite(single))


@settings(max_examples=25, deadline=None)
@given(
    sigma_w=st.floats(1e-6, 1e6),
    sigma_v=st.floats(1e-6, 1e6),
    psi=st.floats(0.0, 0.99),  # bboxtune.filters.validation.PSI_MAX
    seed=st.integers(0, 2**16),
)
def test_finite_input_gives_finite_output(sigma_w: float, sigma_v: float, psi: float, seed: int) -> None:
    y = np.random.default_rng(seed).normal(size=(2, 40, 4)) * 100.0
    y[1, 7] = np.nan
    model = filters.constant_velocity(TAU, ndim=4)
    out = filters.make("kf_cmn", model, sigma_w=sigma_w, sigma_v=sigma_v, psi=psi).run(y)
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize("psi", [-0.1, 1.0, 1.5, np.nan, np.array([0.5, 1.0])])
def test_psi_out_of_range(psi: object) -> None:
    with pytest.raises(ValueError, match="psi"):
        filters.make("kf_cmn", filters.constant_velocity(TAU), psi=psi)
