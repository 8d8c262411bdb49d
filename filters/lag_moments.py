"""Lag moments of per-frame signals over sliding windows, for window filters whose rows are linear in the lag.

UFIR's row of lag k is ``h_k = H F^{−k}``, linear in k for the constant-velocity model (:func:`lag_polynomial`), so
the normal equations of a window with missing frames differ from the clean window's by sums
``Σ_{k<N} k^p s_{n−k}`` (p <= 2) of per-frame signals s (missing frame, undifferenced row, …):
:func:`lag_moments` (exact for 0/1 signals) and :func:`lag_moments_real` (real signals, rounding bounded in T).
"""

from __future__ import annotations

import numpy as np


def lag_polynomial(F: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``c0``, ``c1`` (K,) with ``H F^{−k} = c0 + k c1`` for every k — exact when ``(F − I)² = 0`` (the CV
    model: F^{−k} = I − k (F − I)); ValueError for another F."""
    D = np.asarray(F, dtype=float) - np.eye(F.shape[0])
    if np.any(D @ D != 0.0):
        raise ValueError(f"F={F.tolist()} is not a constant-velocity transition ((F − I)² must be 0)")
    h = np.asarray(H, dtype=float)[0]
    return h, -(h @ D)


def linear_product(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float, float]:
    """Coefficients of (a0 + a1 k)(b0 + b1 k) in powers 0, 1, 2 of k."""
    return a[0] * b[0], a[0] * b[1] + a[1] * b[0], a[1] * b[1]


def lag_moments(s: np.ndarray, N: int, powers: int) -> np.ndarray:
    """``M_p[..., n] = Σ_{k<N} k^p s[..., n−k]`` (powers, ..., T) for p = 0 … powers − 1 (<= 3) and every frame n
    (samples before frame 0 read as 0) of 0/1 signals ``s`` (..., T), by the recursions over n

        M_0(n) = M_0(n−1) + s_n − s_{n−N},      M_1(n) = M_1(n−1) + M_0(n−1) − N s_{n−N},
        M_2(n) = M_2(n−1) + 2 M_1(n) − M_0(n) + s_n − (N−1)² s_{n−N}

    — exact integers (below N³), whatever T. For real-valued signals see :func:`lag_moments_real`."""
    old = np.zeros(s.shape)
    old[..., N:] = s[..., :-N]  # s_{n−N}
    M = np.empty((powers, *s.shape))
    np.cumsum(s - old, axis=-1, out=M[0])
    if powers > 1:
        step = -N * old
        step[..., 1:] += M[0, ..., :-1]
        np.cumsum(step, axis=-1, out=M[1])
    if powers > 2:
        np.cumsum(2.0 * M[1] - M[0] + s - (N - 1) ** 2 * old, axis=-1, out=M[2])
    return M


def lag_moments_real(s: np.ndarray, N: int) -> np.ndarray:
    """:func:`lag_moments` with p = 0, 1 (2, ..., T) of real-valued signals, whose rounding must not grow with T:
    frames cut into blocks of N, in-block prefix sums ``P_q[j, i] = Σ_{o<=i} o^q s_{jN+o}``; the window ending at
    n = jN + i is the part o <= i of block j (lag i − o) and the part o > i of block j − 1 (lag N + i − o), so every
    partial sum stays within two blocks."""
    T = s.shape[-1]
    n_blocks = -(-T // N)
    P = np.zeros((2, *s.shape[:-1], n_blocks + 1, N))  # a zero block before frame 0
    P[0].reshape(*s.shape[:-1], -1)[..., N:N + T] = s
    o = np.arange(N, dtype=float)
    np.multiply(P[0], o, out=P[1])
    np.cumsum(P, axis=-1, out=P)
    here, before = P[..., 1:, :], P[..., :-1, -1:] - P[..., :-1, :]  # o <= i in block j; o > i in block j − 1
    M = np.empty(here.shape)
    M[0] = here[0] + before[0]
    M[1] = o * here[0] - here[1] + (N + o) * before[0] - before[1]
    return M.reshape(2, *s.shape[:-1], -1)[..., :T]
