"""Interacting multiple model (IMM) filter over two KF tunings: the switching baseline a tracking engineer tries first.

Every coordinate follows the two-state constant-velocity model of the back ends (``bboxtune.filters.model``): F = [[1, τ],
[0, 1]], H = [1, 0], B = [τ²/2, τ]ᵀ, white measurement noise R = σ_v². Two models differ in their process noise
only: Q_j = (g_j σ_w)² B Bᵀ with gains g = ``gains`` (default 1 — the nominal "quiet" model — and 10, a manoeuvre
model). Mode switches follow a Markov chain with P(stay) = ``stay``. One cycle (Blom & Bar-Shalom, IEEE TAC 1988;
Bar-Shalom, Li & Kirubarajan 2001, §11.6.6):

    c̄_j = Σ_i p_ij μ_i,   μ_i|j = p_ij μ_i / c̄_j                                          (IMM-1 mixing weights)
    x⁰_j = Σ_i μ_i|j x_i,  P⁰_j = Σ_i μ_i|j (P_i + (x_i − x⁰_j)(x_i − x⁰_j)ᵀ)               (IMM-2 mixing)
    x⁻_j = F x⁰_j,  P⁻_j = F P⁰_j Fᵀ + Q_j;  ε_j = y − H x⁻_j,  S_j = H P⁻_j Hᵀ + R         (IMM-3 mode-matched KF)
    K_j = P⁻_j Hᵀ / S_j,  x_j = x⁻_j + K_j ε_j,  P_j = (I − K_j H) P⁻_j
    μ_j ∝ c̄_j N(ε_j; 0, S_j),   x̂ = Σ_j μ_j x_j                                          (IMM-4 mode update, output)

A missing measurement (NaN) skips the update: x_j = x⁻_j, P_j = P⁻_j, μ_j = c̄_j (the mode probabilities are
predicted by the chain; filterpy's ``IMMEstimator`` without ``update`` keeps μ instead). Start: at a channel's first finite
measurement x_j = [y, 0], P_j = diag(σ_v², (10³ σ_v / τ)²) (the back ends' start covariance), μ = (½, ½); frames
before it are NaN. Conventions as :func:`bboxtune.agents.policies.adaptive.sage_husa_positions`: y (B, T, M), τ scalar or (B,),
output (B, T, M) position estimates. Tested against filterpy's ``IMMEstimator``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bboxtune.filters.kalman_core import VELOCITY_PRIOR_SCALE


@dataclass(frozen=True)
class IMMConfig:
    """The two models and the switching chain."""

    gains: tuple[float, float] = (1.0, 10.0)  # σ_w multipliers of the two models (quiet, manoeuvre)
    stay: float = 0.95  # P(mode_k = mode_{k−1}), in (0.5, 1)


def imm_positions(y: np.ndarray, tau: float | np.ndarray, sigma_w: float | np.ndarray, sigma_v: float | np.ndarray,
                  config: IMMConfig = IMMConfig()) -> np.ndarray:
    """IMM position estimates (B, T, M) of measurements ``y`` (B, T, M); σ_w (px/s²), σ_v (px) scalars or (B,)."""
    if not 0.5 < config.stay < 1.0 or min(config.gains) <= 0:
        raise ValueError(f"IMMConfig {config}: stay must lie in (0.5, 1) and gains be > 0")
    y = np.asarray(y, dtype=float)
    B, T, M = y.shape
    col = lambda v: np.broadcast_to(np.asarray(v, dtype=float).reshape(-1, 1), (B, M))  # noqa: E731
    tau, sw, sv = col(tau), col(sigma_w), col(sigma_v)
    R = sv**2
    q = [(g * sw) ** 2 for g in config.gains]  # Q_j = q_j B Bᵀ
    b0, b1 = tau**2 / 2, tau
    p = np.array([[config.stay, 1 - config.stay], [1 - config.stay, config.stay]])  # p[i, j] = P(j | i)
    x = np.zeros((2, 2, B, M))  # model, state component (position, velocity)
    P = np.zeros((2, 3, B, M))  # model, (P00, P01, P11)
    mu = np.full((2, B, M), 0.5)
    started = np.zeros((B, M), bool)
    out = np.full((B, T, M), np.nan)
    for k in range(T):  # loop over time only
        z = y[:, k]
        seen = np.isfinite(z)
        new = seen & ~started
        if new.any():  # a channel's first measurement starts it
            x[:, 0] = np.where(new, z, x[:, 0])
            x[:, 1] = np.where(new, 0.0, x[:, 1])
            P[:, 0] = np.where(new, R, P[:, 0])
            P[:, 1] = np.where(new, 0.0, P[:, 1])
            P[:, 2] = np.where(new, (VELOCITY_PRIOR_SCALE * sv / tau) ** 2, P[:, 2])
            mu[:] = np.where(new, 0.5, mu)
        run = started  # channels that were started before this frame get a full cycle
        if run.any():
            cbar = np.einsum("ij,ibm->jbm", p, mu)  # (IMM-1)
            w = p[:, :, None, None] * mu[:, None] / cbar[None]  # w[i, j] = μ_i|j
            x0 = np.einsum("ijbm,icbm->jcbm", w, x)  # (IMM-2)
            dx = x[:, None] - x0[None]  # (i, j, c, B, M)
            P0 = np.stack([np.einsum("ijbm,ijbm->jbm", w, P[:, None, a] + dx[:, :, c] * dx[:, :, d])
                           for a, (c, d) in enumerate(((0, 0), (0, 1), (1, 1)))], axis=1)
            xp = np.stack([x0[:, 0] + tau * x0[:, 1], x0[:, 1]], axis=1)  # (IMM-3) F x⁰
            qj = np.stack(q)
            P00 = P0[:, 0] + 2 * tau * P0[:, 1] + tau**2 * P0[:, 2] + qj * b0 * b0
            P01 = P0[:, 1] + tau * P0[:, 2] + qj * b0 * b1
            P11 = P0[:, 2] + qj * b1 * b1
            S = P00 + R
            eps = np.where(seen, z, 0.0) - xp[:, 0]
            K0, K1 = P00 / S, P01 / S
            upd = run & seen
            xn = np.stack([xp[:, 0] + K0 * eps, xp[:, 1] + K1 * eps], axis=1)
            Pn = np.stack([(1 - K0) * P00, (1 - K0) * P01, P11 - K1 * P01], axis=1)
            like = np.exp(-0.5 * eps**2 / S) / np.sqrt(2 * np.pi * S)
            mun = cbar * like
            total = mun.sum(axis=0)
            mun = np.where(total > 0, mun / np.where(total > 0, total, 1.0), cbar)  # (IMM-4); underflow: keep c̄
            x = np.where(run, np.where(upd, xn, xp), x)
            P = np.where(run, np.where(upd, Pn, np.stack([P00, P01, P11], axis=1)), P)
            mu = np.where(run, np.where(upd, mun, cbar), mu)
        started = started | new
        out[:, k] = np.where(started, np.einsum("jbm,jbm->bm", mu, x[:, 0]), np.nan)
    return out
