"""Kwon's minimum-variance FIR filter in the C̄_N, Ḡ_N, Π_N form of [Mo-FIR] (eqs. 5–13; notes §1.7).

[Mo-FIR] writes the filter for the forward-Euler model ``s_{k+1} = A s_k + w_k`` as a one-step predictor of s_k
from ``z_{k−N} … z_{k−1}``. Here the same construction is applied to this project's model (``x_l = F x_{l−1} +
B w_l``, ``y_l = H x_l + v_l``) as a *filter* on the window ``y_m … y_n`` (m = n − L + 1, L = N samples), so the
noise inputs are ``W = [w_{m+1} … w_n]`` and x_n is reached from x_m in L − 1 steps::

    C_N = [H; H F; …; H F^{L−1}]                 (11)    Y = C_N x_m + G_N W + V
    G_N[i, j−1] = H F^{i−j} B  (j ≤ i)           (12)
    M_N = [F^{L−2} B … F B  B]                   (13)    x_n = F^{L−1} x_m + M_N W
    C̄_N = C_N F^{−(L−1)}                        (7)     Y = C̄_N x_n + Ḡ_N W + V
    Ḡ_N = G_N − C̄_N M_N                         (8)
    Π_N = Ḡ_N diag(Q … Q) Ḡ_Nᵀ + diag(R … R)      (9)     Q = σ_w², R = σ_v²
    x̂_n = (C̄_Nᵀ Π_N⁻¹ C̄_N)⁻¹ C̄_Nᵀ Π_N⁻¹ Y          (5)

This is the same estimator as OUFIR (:mod:`bboxtune.filters.oufir`), reached by a different formula (GLS referenced to x_n
instead of a constrained minimum-variance gain referenced to x_m); the tests check they agree. [Mo-FIR]'s δ
experiment (the truth sampled every τ + δ while the filter assumes τ) is a model error this filter absorbs for
constant-velocity motion: its position estimate is unbiased for every straight line whatever the time scale.

Conventions as in :mod:`bboxtune.filters.oufir`: missing samples are dropped from Y, C̄_N, Ḡ_N and Π_N; start-up windows
are the full-horizon filter on the samples so far (grown by the OUFIR recursion, the same estimator); when Π_N is
too ill-conditioned for its Cholesky factor (``1 + ratio² ‖Ḡ_N‖²_F > COND_MAX``) the gain is taken from the
equivalent ML least-squares form of :func:`bboxtune.filters.oufir.window_gls_gain`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from bboxtune.filters.oufir import COND_MAX, OUFIR, window_gls_gain, window_model


def kwon_gain(F: np.ndarray, H: np.ndarray, B: np.ndarray, valid: np.ndarray, sigma_w: float,
              sigma_v: float) -> np.ndarray:
    """Kwon FIR gain (K, L) of one window by [Mo-FIR] eqs. (5)–(13); zero at invalid samples."""
    valid = np.asarray(valid, bool)
    ratio = sigma_w / sigma_v  # Π_N / σ_v² = ratio² Ḡ_N Ḡ_Nᵀ + I: only the ratio matters
    F_last, C_N, G_N, M_N = window_model(F, H, B, valid.size)  # eqs. (11), (12), (13)
    C_bar = np.linalg.solve(F_last.T, C_N.T).T  # eq. (7): C_N F^{−(L−1)}
    G_bar = G_N - C_bar @ M_N  # eq. (8)
    idx = np.flatnonzero(valid)
    C_bar, G_bar = C_bar[idx], G_bar[idx]
    if 1.0 + ratio**2 * np.sum(G_bar**2) > COND_MAX:
        return window_gls_gain(F, H, B, valid, ratio)[0]
    root = np.linalg.cholesky(ratio**2 * (G_bar @ G_bar.T) + np.eye(idx.size))  # eq. (9), Π_N / σ_v²
    Q, R = np.linalg.qr(sla.solve_triangular(root, C_bar, lower=True))  # Π_N^{−1/2} C̄_N = Q R
    W = np.zeros((F.shape[0], valid.size))
    W[:, idx] = sla.solve_triangular(root, sla.solve_triangular(R, Q.T).T, lower=True, trans=1).T  # eq. (5)
    return W


class KwonFIR(OUFIR):
    """Kwon's minimum-variance FIR filter ([Mo-FIR] eqs. 5–13), filtered form on the last N frames.

    Parameters as :class:`bboxtune.filters.oufir.OUFIR`: ``sigma_w`` (acceleration noise std, units/s²), ``sigma_v``
    (measurement noise std, units), ``horizon`` N (integer >= 2; None → :func:`bboxtune.filters.horizon.rule_horizon`),
    each a scalar or (B,) per track.

    >>> import numpy as np
    >>> from bboxtune import filters
    >>> f = filters.make("fir", filters.constant_velocity(0.05), sigma_w=50.0, sigma_v=4.0, horizon=20)
    >>> bool(np.allclose(f.run(np.arange(30.0)[:, None])[-1], [29.0, 20.0]))  # a ramp is reproduced exactly
    True
    """

    name = "fir"

    def window_gain(self, valid: np.ndarray, params: dict[str, float | int]) -> np.ndarray:
        axis = self.model.axis()
        return kwon_gain(axis.F, axis.H, axis.B, valid, params["sigma_w"], params["sigma_v"])
