"""The optimal-horizon rule of the UFIR literature (Ramírez-Echeverría, Sarr, Shmaliy, IEEE TSP 2014)."""

from __future__ import annotations

import numpy as np

from bboxtune.filters.validation import check_sigma, check_tau


def n_opt(sigma_v: float | np.ndarray, sigma_w: float | np.ndarray, tau: float | np.ndarray) -> float | np.ndarray:
    """``N_opt = sqrt(12 σ_v / (τ² σ_w))`` ([Shmaliy-CMN] §II-D; [PaleRamon-BBox] eq. for N_opt).

    Convention: σ_w is the std of white *acceleration* noise entering through ``B = [τ²/2, τ]ᵀ`` (the
    velocity increment per step has std τσ_w) and σ_v the std of the white measurement noise. (If σ_w were
    the std of the velocity increment itself the rule would read sqrt(12 σ_v / (τ σ_w)).)

    >>> round(float(n_opt(4, 50, 0.05)), 1), round(float(n_opt(2, 10, 0.1)), 1), round(float(n_opt(3, 10, 0.03)), 1)
    (19.6, 15.5, 63.2)
    """
    sv = check_sigma("sigma_v", sigma_v)
    sw = check_sigma("sigma_w", sigma_w)
    t = check_tau(tau)
    out = np.sqrt(12.0 * sv / (t**2 * sw))
    return float(out) if out.ndim == 0 else out


def rule_horizon(sigma_v: float | np.ndarray, sigma_w: float | np.ndarray, tau: float | np.ndarray, K: int,
                 max_horizon: int = 10_000) -> int | np.ndarray:
    """The rule's horizon as a usable integer: ``round(N_opt)`` clipped to [K, max_horizon]
    (clipping is part of this function's definition; the unclipped value is :func:`n_opt`)."""
    n = np.minimum(np.maximum(np.rint(n_opt(sigma_v, sigma_w, tau)), K), max_horizon).astype(np.int64)
    return int(n) if n.ndim == 0 else n
