"""The CMN filters across missing frames (issue 33; docs/notes/kf-cmn-gaps.md): at ψ = 0 each equals its white-noise
filter on tracks with long runs of missing frames, whole or split into carried pieces; KF-CMN at ψ > 0 equals the
time-correlated reference with the gap-spanning difference z_n = y_n − ψ^{g+1} y_m and, independently, the Kalman
filter of the state augmented with the noise v_n; and it beats the old predict-only treatment of the first y after a
gap, and the KF, on simulated coloured-noise tracks."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from bboxtune import filters
from bboxtune.filters.base import Carry
from tests.filters.test_carry import assert_same, assert_same_carry, run_in_pieces
from tests.filters.test_kf import assert_rel, simulate
from tests.filters.test_kf_cmn import P0, X0, cmn_matrices, simulate_cmn, time_correlated

TAU = 0.05
AXIS = filters.constant_velocity(TAU).axis()


def runs_missing(rng: np.random.Generator, T: int, longest: int = 30, longest_seen: int = 30,
                 first: bool | None = None) -> np.ndarray:
    """A Gilbert–Elliott-like mask (T,), True = missing: alternating runs of missing and detected frames of lengths
    drawn from 1 … ``longest`` and 1 … ``longest_seen`` (equal: about half the frames missing); ``first``: whether
    frame 0 is missing (None: at random)."""
    missing, state = np.zeros(T, bool), rng.random() < 0.5 if first is None else first
    n = 0
    while n < T:
        length = int(rng.integers(1, (longest if state else longest_seen) + 1))
        missing[n:n + length] = state
        n, state = n + length, not state
    return missing


def gapped_boxes(seed: int, B: int = 5, T: int = 240) -> np.ndarray:
    """Box tracks (B, T, 4) with 40–60 % of their frames missing in runs (whole boxes; track 1 also loses one
    coordinate on its own, so its channels have different missing patterns)."""
    rng = np.random.default_rng(seed)
    y = simulate(rng, T, 4, 40.0, 2.0, B=B)
    for b in range(B):
        while not 0.4 <= (mask := runs_missing(rng, T)).mean() <= 0.6:
            pass
        y[b, mask] = np.nan
    y[1, runs_missing(rng, T, 10), 2] = np.nan
    return y


WHITE = {"kf_cmn": "kf", "ufir_cmn": "ufir"}
PARAMS = {  # per-track arrays (B = 5)
    "kf_cmn": {"sigma_w": np.array([1.0, 30.0, 300.0, 1321.0, 50.0]), "sigma_v": np.array([2.0, 3.0, 0.5, 0.34, 4.0])},
    "ufir_cmn": {"horizon": np.array([3, 8, 20, 45, 120])},
}


@pytest.mark.parametrize("name", ["kf_cmn", "ufir_cmn"])
def test_psi_zero_equals_the_white_noise_filter_across_gaps(name: str) -> None:
    y = gapped_boxes(1)
    model = filters.constant_velocity(1 / 30, ndim=4)
    cmn = filters.make(name, model, psi=0.0, **PARAMS[name]).run(y)
    white = filters.make(WHITE[name], model, **PARAMS[name]).run(y)
    assert_same(cmn, white, 1e-9)
    if name == "kf_cmn":
        np.testing.assert_array_equal(cmn, white)  # bit for bit (module docstring)
        single = filters.make(name, model, psi=0.0, sigma_w=1321.0, sigma_v=0.34).run(y[3])
        np.testing.assert_array_equal(single, filters.make("kf", model, sigma_w=1321.0, sigma_v=0.34).run(y[3]))


@pytest.mark.parametrize("name", ["kf_cmn", "ufir_cmn"])
def test_psi_zero_split_runs_equal_the_whole_white_noise_run(name: str) -> None:
    """run_from split at a gap's first and last frame, inside gaps and between them, chained."""
    y = gapped_boxes(2)
    model = filters.constant_velocity(1 / 30, ndim=4)
    missing = np.isnan(y[0, :, 0])
    starts = np.flatnonzero(missing[1:] & ~missing[:-1]) + 1  # first missing frame of each gap of track 0
    ends = np.flatnonzero(~missing[1:] & missing[:-1]) + 1  # first frame after a gap
    cuts = sorted({int(starts[1]), int(starts[2]) + 1, int(ends[2]), int(ends[3]) + 2, 150, 151, 239})
    whole = filters.make(WHITE[name], model, **PARAMS[name]).run(y)
    cmn = filters.make(name, model, psi=0.0, **PARAMS[name])
    assert_same(run_in_pieces(cmn, y, cuts)[0], whole, 1e-9)
    for t in cuts:
        assert_same(run_in_pieces(cmn, y, [t])[0], whole, 1e-9)


@pytest.mark.parametrize("psi", [0.3, 0.8, 0.95])
def test_gap_spanning_update_matches_the_time_correlated_reference(psi: float) -> None:
    rng = np.random.default_rng(int(psi * 100) + 3)
    _, y = simulate_cmn(rng, 500, 30.0, 3.0, psi)
    y[runs_missing(rng, 500, first=True)] = np.nan  # leading frames missing: predict from the prior first
    ours = filters.make("kf_cmn", filters.constant_velocity(TAU), sigma_w=30.0, sigma_v=3.0, psi=psi,
                        x0=X0, P0=P0).run(y[:, None])
    assert_rel(ours, time_correlated(y, 30.0, 3.0, psi), 1e-9)


def augmented_state(y: np.ndarray, sigma_w: float, sigma_v: float, psi: float) -> np.ndarray:
    """The exact filter of the model by another route: filterpy's KalmanFilter on [p, v, v_n] with
    v_n = ψ v_{n−1} + ξ_n, y_n = p_n + v_n (no further noise), predict-only where y_n is missing; the prior of
    v_{−1} is stationary, as KF-CMN's first update on y assumes."""
    def with_noise(state: np.ndarray, noise: float) -> np.ndarray:  # blockdiag(state block, noise entry)
        out = np.zeros((3, 3))
        out[:2, :2], out[2, 2] = state, noise
        return out

    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.F, kf.Q = with_noise(AXIS.F, psi), with_noise(sigma_w**2 * AXIS.B @ AXIS.B.T, sigma_v**2)
    kf.H, kf.R = np.array([[1.0, 0.0, 1.0]]), np.zeros((1, 1))
    kf.x, kf.P = np.r_[X0, 0.0], with_noise(P0, sigma_v**2 / (1 - psi**2))
    out = []
    for y_n in y:
        kf.predict()
        kf.update(None if np.isnan(y_n) else y_n)
        out.append(kf.x[:2].copy())
    return np.array(out)


@pytest.mark.parametrize("psi", [0.0, 0.5, 0.9])
def test_equals_the_augmented_state_filter(psi: float) -> None:
    rng = np.random.default_rng(11)
    _, y = simulate_cmn(rng, 400, 50.0, 4.0, psi)
    y[runs_missing(rng, 400)] = np.nan
    ours = filters.make("kf_cmn", filters.constant_velocity(TAU), sigma_w=50.0, sigma_v=4.0, psi=psi,
                        x0=X0, P0=P0).run(y[:, None])
    assert_rel(ours, augmented_state(y, 50.0, 4.0, psi), 1e-9)


def test_decorrelated_form_from_the_previous_frame_is_the_same_filter() -> None:
    """The de-correlated form written from frame n − 1 (docs/notes/kf-cmn-gaps.md, eq. G8: x⁻ = A_g x + Λ_g z_n,
    P⁻ = A_g P Aᵀ_g + 𝒬_g with 𝒬_g = (I − Λ_g H) Q_g (I − Λ_g D_g)ᵀ − (I − Λ_g D_g)(Q_g − Q)(I − Λ_g D_g)ᵀ, then
    a standard update with D_g, R̄_g) equals the time-correlated update the filter uses, here where it is
    well-conditioned (σ_w τ²/σ_v ~ 0.02)."""
    rng = np.random.default_rng(5)
    sigma_w, sigma_v, psi = 30.0, 3.0, 0.8
    _, y = simulate_cmn(rng, 300, sigma_w, sigma_v, psi)
    y[runs_missing(rng, 300)] = np.nan
    F, H, Q, I = AXIS.F, AXIS.H, sigma_w**2 * AXIS.B @ AXIS.B.T, np.eye(2)
    x, P, last, out = X0, P0, None, []
    for n, y_n in enumerate(y):
        if np.isnan(y_n) or last is None:  # predict; the first finite y: a standard update
            x, P = F @ x, F @ P @ F.T + Q
            if not np.isnan(y_n):
                S = P[0, 0] + sigma_v**2 / (1 - psi**2)
                K = P[:, 0] / S
                x, P, last = x + K * (y_n - x[0]), P - np.outer(K, K) * S, n
        else:  # from frame n − 1, across g missing frames
            g = n - last - 1
            m = cmn_matrices(sigma_w, sigma_v, psi, g)
            Q_g = sum(np.linalg.matrix_power(F, j) @ Q @ np.linalg.matrix_power(F, j).T for j in range(g + 1))
            var_e = sigma_v**2 * sum(psi ** (2 * k) for k in range(g + 1))
            D, R_bar, M = m["D"], m["R_bar"][0, 0], m["M"]
            Lam = M / (H @ M + var_e)  # Λ_g = M_g (H M_g + σ_g²)⁻¹
            A = (I - Lam @ D) @ F
            Q_tab = (I - Lam @ H) @ Q_g @ (I - Lam @ D).T - (I - Lam @ D) @ (Q_g - Q) @ (I - Lam @ D).T
            z = y_n - psi ** (g + 1) * y[last]
            x, P = A @ x + Lam[:, 0] * z, A @ P @ A.T + Q_tab
            S = (D @ P @ D.T)[0, 0] + R_bar
            K = (P @ D.T)[:, 0] / S
            x, P, last = x + K * (z - (D @ x)[0]), P - np.outer(K, K) * S, n
        out.append(x)
    assert_rel(np.array(out), time_correlated(y, sigma_w, sigma_v, psi), 1e-9)


def test_carried_pieces_equal_the_whole_run_across_gaps() -> None:
    """ψ > 0, per-track parameters: pieces of 1–9 frames (cuts everywhere: inside gaps, at their ends) chained
    through the carry, which holds the last finite y and the frames missed since."""
    y = gapped_boxes(3)
    model = filters.constant_velocity(1 / 30, ndim=4)
    f = filters.make("kf_cmn", model, psi=np.array([0.3, 0.6, 0.9, 0.99, 0.0]), **PARAMS["kf_cmn"])
    whole, carry_whole = f.run_from(y)
    cuts = list(np.cumsum(np.random.default_rng(4).integers(1, 10, 60)))
    pieces, carry = run_in_pieces(f, y, [int(c) for c in cuts if c < y.shape[1]])
    assert_same(pieces, whole, 1e-10)
    assert_same_carry(carry, carry_whole)
    last = [np.flatnonzero(~np.isnan(y[b, :, 0]))[-1] for b in range(len(y))]
    np.testing.assert_array_equal(carry.missed[:, 0], y.shape[1] - 1 - np.array(last))
    np.testing.assert_array_equal(carry.y_last[:, 0], y[np.arange(len(y)), last, 0])


def test_a_carry_without_missed_still_continues() -> None:
    """A Carry built without ``missed`` (as before issue 33) counts as y_last being the last frame's measurement;
    a measured coordinate without a finite y_last updates its next y like a first measurement with a prior."""
    y = simulate(np.random.default_rng(6), 80, 1, 20.0, 2.0)
    f = filters.make("kf_cmn", filters.constant_velocity(TAU), sigma_w=20.0, sigma_v=2.0, psi=0.7)
    whole = f.run(y)
    first, carry = f.run_from(y[:40])
    old_style = Carry(x=carry.x, P=carry.P, y_last=carry.y_last, measured=carry.measured)
    assert_same(np.concatenate([first, f.run_from(y[40:], old_style)[0]]), whole, 1e-12)
    unknown = Carry(x=carry.x, P=carry.P, y_last=np.full((1, 1), np.nan), measured=carry.measured)
    rest = f.run_from(y[40:], unknown)[0]
    assert np.all(np.isfinite(rest)) and not np.allclose(rest, whole[40:])


def test_bad_missed_is_refused() -> None:
    y = simulate(np.random.default_rng(7), 30, 1, 20.0, 2.0)
    f = filters.make("kf_cmn", filters.constant_velocity(TAU))
    _, carry = f.run_from(y[:10])
    for missed in (np.full((1, 1), -1.0), np.full((1, 1), 1.5), np.full((1, 1), np.nan)):
        with pytest.raises(ValueError, match=r"carry\.missed"):
            f.run_from(y[10:], Carry(x=carry.x, P=carry.P, y_last=carry.y_last, measured=carry.measured,
                                     missed=missed))
    with pytest.raises(ValueError, match=r"carry\.y_last is finite"):
        f.run_from(y[10:], Carry(x=carry.x, P=carry.P, y_last=carry.y_last, measured=np.zeros((1, 1), bool)))


def test_many_gap_lengths_in_one_call() -> None:
    """More gap lengths than int8 frame kinds hold (130 > 123): one track per length, batched = one by one."""
    n = 130
    y = simulate(np.random.default_rng(8), 200, 1, 20.0, 2.0, B=n)
    for g in range(1, n + 1):
        y[g - 1, 30:30 + min(g, 150)] = np.nan
    y[n - 1, 181:183] = np.nan  # and a short one after the long one
    model = filters.constant_velocity(TAU)
    params = {"sigma_w": 20.0, "sigma_v": 2.0}
    batched = filters.make("kf_cmn", model, psi=0.8, **params).run(y)
    for b in (0, 57, 122, 129):
        assert_same(batched[b], filters.make("kf_cmn", model, psi=0.8, **params).run(y[b]), 1e-12)
    np.testing.assert_array_equal(filters.make("kf_cmn", model, psi=0.0, **params).run(y),
                                  filters.make("kf", model, **params).run(y))


def predict_only_reference(y: np.ndarray, sigma_w: float, sigma_v: float, psi: float) -> np.ndarray:
    """The treatment before issue 33 (filterpy): no z without a finite y_{n−1}, so the first y after a gap is
    predict-only; otherwise as :func:`tests.filters.test_kf_cmn.time_correlated`."""
    m = cmn_matrices(sigma_w, sigma_v, psi)
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F, kf.Q, kf.M, kf.x, kf.P = m["F"], m["Q"], m["M"], X0.copy(), P0.copy()
    out = []
    for n in range(len(y)):
        kf.predict()
        if n == 0:
            kf.update(y[0], R=np.eye(1) * sigma_v**2 / (1 - psi**2), H=m["H"])
        elif np.isnan(y[n]) or np.isnan(y[n - 1]):
            kf.update(None)
        else:
            kf.update_correlated(np.array([y[n] - psi * y[n - 1]]), R=m["R_bar"], H=m["D"])
        out.append(kf.x.copy())
    return np.array(out)


@pytest.mark.parametrize("psi", [0.6, 0.75, 0.9])
def test_spanning_gaps_beats_predict_only_and_the_kf(psi: float) -> None:
    """Simulated CMN tracks with 40 % of the frames missing in runs: position RMSE over all frames (gaps included)
    of the fixed KF-CMN < the old predict-only treatment < … and < a KF with R = var(v) (stationary)."""
    rng = np.random.default_rng(int(psi * 100))
    sigma_w, sigma_v, T = 50.0, 4.0, 1500
    errors: dict[str, list[np.ndarray]] = {"fixed": [], "predict_only": [], "kf": []}
    model = filters.constant_velocity(TAU)
    for _ in range(3):
        truth, y = simulate_cmn(rng, T, sigma_w, sigma_v, psi)
        while not 0.35 <= (mask := runs_missing(rng, T, 20, 30, first=False)).mean() <= 0.45:  # 40 % on average
            pass
        y[mask] = np.nan
        fixed = filters.make("kf_cmn", model, sigma_w=sigma_w, sigma_v=sigma_v, psi=psi, x0=X0, P0=P0).run(y[:, None])
        kf = filters.make("kf", model, sigma_w=sigma_w, sigma_v=sigma_v / np.sqrt(1 - psi**2), x0=X0, P0=P0)
        errors["fixed"].append(fixed[50:, 0] - truth[50:])
        errors["predict_only"].append(predict_only_reference(y, sigma_w, sigma_v, psi)[50:, 0] - truth[50:])
        errors["kf"].append(kf.run(y[:, None])[50:, 0] - truth[50:])
    rmse = {k: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for k, v in errors.items()}
    assert rmse["fixed"] < 0.97 * rmse["predict_only"] and rmse["fixed"] < 0.97 * rmse["kf"], rmse
