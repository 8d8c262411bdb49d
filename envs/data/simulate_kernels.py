"""Compiled kernels of the Gauss–Markov simulation (:mod:`bboxtune.envs.data.simulate`), batched over tracks.

Only the deterministic arithmetic runs here — the CMN recursion (2), the integration of the motion (1) and the
reflection of the log sizes at their bounds; every random number is still drawn by numpy's ``Generator`` in
:mod:`bboxtune.envs.data.simulate`. Each kernel does the operations of its numpy reference in the same order
(``np.cumsum`` and ``scipy.signal.lfilter`` are sequential sums, ``%`` is ``np.mod``: the exact fmod with Python's
sign rule), so its results equal the reference's bit for bit: the episodes of a seed do not depend on ``$BBOXTUNE_JIT``.
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit


@jit.kernel
def colour(e: np.ndarray, psi: np.ndarray, start_std: np.ndarray) -> None:
    """The CMN (2) in place on the scaled white noise ``e`` (B, T, C): track b's frame 0 divided by ``start_std[b]``
    = √(1 − ψ_b²) (the stationary start), then v_n = ψ_b v_{n−1} + ξ_n (2) (``lfilter([1], [1, −ψ])``'s
    operations: ξ_n + ψ v_{n−1})."""
    B, T, C = e.shape
    for b in range(B):
        for c in range(C):
            e[b, 0, c] /= start_std[b]
        if psi[b] == 0.0:  # white noise: lfilter is skipped in the reference
            continue
        for n in range(1, T):
            for c in range(C):
                e[b, n, c] = e[b, n, c] + psi[b] * e[b, n - 1, c]


@jit.kernel
def integrate(p0: np.ndarray, v0: np.ndarray, w: np.ndarray, tau: np.ndarray, delta: np.ndarray, low: np.ndarray,
              high: np.ndarray, state: np.ndarray) -> None:
    """x_n = F(τ + δ) x_{n−1} + B(τ) w_n (1) of the C coordinates of B tracks from the scaled acceleration noise
    ``w`` (B, T − 1, C) and the start ``p0``, ``v0`` (B, C), per track ``tau``, ``delta`` (B,), into ``state``
    (B, T, 2C) = [positions, velocities]. As the reference, v_n = v_0 + τ Σ_{i≤n} w_i and
    p_n = p_0 + Σ_{i≤n} ((τ + δ) v_{i−1} + τ²/2 w_i) (running sums). The last ``low.shape[1]`` coordinates (log sizes)
    are then reflected into [low, high] (B, ·) (``sim_motion.reflect``: mirrored k times, the rate negated when k is odd)."""
    B, T1, C = w.shape
    n_reflected = low.shape[1]
    for b in range(B):
        step_p, half_tau2 = tau[b] + delta[b], 0.5 * (tau[b] * tau[b])
        for c in range(C):
            state[b, 0, c], state[b, 0, C + c] = p0[b, c], v0[b, c]
            sum_w = sum_p = 0.0
            v_prev = v0[b, c]
            for n in range(T1):
                sum_w = w[b, n, c] if n == 0 else sum_w + w[b, n, c]
                step = step_p * v_prev + half_tau2 * w[b, n, c]  # p_n − p_{n−1} (1)
                sum_p = step if n == 0 else sum_p + step
                v_prev = v0[b, c] + tau[b] * sum_w  # v_n = v_{n−1} + τ w_n (1), as v_0 + τ cumsum(w)
                state[b, n + 1, c], state[b, n + 1, C + c] = p0[b, c] + sum_p, v_prev
        for j in range(n_reflected):
            c = C - n_reflected + j
            lo, hi = low[b, j], high[b, j]
            width = hi - lo
            for n in range(T1 + 1):
                x = state[b, n, c]
                if x < lo or x > hi:
                    u = (x - lo) % (2.0 * width)  # within one back-and-forth period (np.mod's and Python's sign rule)
                    if u > width:  # an odd number of reflections: on the way back
                        state[b, n, c] = lo + (2.0 * width - u)
                        state[b, n, C + c] = -state[b, n, C + c]
                    else:
                        state[b, n, c] = lo + u


@jit.kernel
def measure(state: np.ndarray, growth: np.ndarray, sizes0: np.ndarray, cmn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The truth and measurements (B, T, M) (M = ``cmn.shape[2]``) of the integrated ``state`` (B, T, 2M), whose box
    sizes (coordinates 2, 3 when ``growth`` (B, T, 2) = exp(ℓ) is not empty) become w = w_0 exp(ℓ) and their rates
    ẇ = w ℓ̇ (``sizes0`` (B, 2) = w_0, h_0) in place; y = truth + CMN (3)."""
    B, T, M = cmn.shape
    truth, y = np.empty((B, T, M)), np.empty((B, T, M))
    for b in range(B):
        for n in range(T):
            for j in range(growth.shape[2]):
                size = sizes0[b, j] * growth[b, n, j]
                state[b, n, 2 + j] = size
                state[b, n, M + 2 + j] *= size
            for c in range(M):
                truth[b, n, c] = state[b, n, c]
                y[b, n, c] = state[b, n, c] + cmn[b, n, c]
    return truth, y
