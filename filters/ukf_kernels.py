"""Compiled kernel of the UKF's sigma-point gain recursion (:func:`bboxtune.filters.ukf.sigma_gain_recursion`, its numpy
reference): the two-state covariance recursion of G rows through five centred sigma points per frame.

The same equations as the reference (Cholesky root of (n + λ) P, the sigma points χ = [0, ±L_0, ±L_1], the weighted
sums Σ W^c over s = 0 … 4, P⁻ = Σ W^c (Fχ)(Fχ)ᵀ + Q, the update through points re-drawn from P⁻, P⁻ − K S Kᵀ
symmetrised) on scalars, row by row, in the reference's order of floating-point operations, so that they agree with
it to rounding and mostly bit for bit (property tests: tests/filters/test_ukf_kernels.py).
Like :func:`bboxtune.filters.kalman_kernels.gain_recursion` it stops a row once its posterior covariance repeats bit
for bit after its last change of frame kind, and derives the frame the reference stops at from the rows' stops.
A covariance that is not positive definite (e.g. a singular prior) has no Cholesky root: the kernel then gives up
(None) and the reference, which takes the eigen-square-root there, runs instead.
"""

from __future__ import annotations

import math

import numpy as np

from bboxtune.filters import jit
from bboxtune.filters.kalman_core import INIT, UPDATE_Y
from bboxtune.filters.kalman_kernels import repeat_later, settled_from, stop_frame


def sigma_gain_recursion(kinds: np.ndarray, params: np.ndarray, P_start: np.ndarray, F: np.ndarray,
                         b: np.ndarray) -> tuple[np.ndarray, int, np.ndarray] | None:
    """:func:`bboxtune.filters.ukf.sigma_gain_recursion` compiled: affine coefficients (T, 6, G) of the rows' frame
    ``kinds`` (G, T) with parameters [σ_w, σ_v, α, β, κ] (G, 5), transition ``F`` (2, 2) and noise input ``b`` (2,)
    (Q = σ_w² b bᵀ) from ``P_start`` (2, 2, G); the steady frame (T if none); the posterior covariance (2, 2, G) at the
    last frame. None where a covariance on the way is not positive definite (run the reference)."""
    kinds = np.ascontiguousarray(kinds, dtype=np.int8 if kinds.dtype == np.int8 else np.int32)
    f64 = [np.ascontiguousarray(a, dtype=np.float64) for a in (params, P_start, F, b)]
    by_row, steady, P_end, definite = _sigma_rows(kinds, *f64)
    if not definite:
        return None
    return by_row.transpose(1, 2, 0), int(steady), P_end  # (T, 6, G): a view of the rows' coefficients (G, T, 6)


@jit.kernel(inline=True)
def _covariance(w0: float, wi: float, a0: float, a1: float, c0: float, c1: float) -> tuple:
    """Σ_s W^c_s χ_s χ_sᵀ of the centred points χ = [0, ±(a0, a1), ±(c0, c1)] in order s = 0 … 4 (weights W^c_0 =
    ``w0``, the others ``wi``), each term (W^c_s χ_si) χ_sj as the reference's einsum forms it: entries (00, 01, 10,
    11)."""
    s00 = w0 * 0.0 * 0.0 + wi * a0 * a0 + wi * c0 * c0 + wi * (-a0) * (-a0) + wi * (-c0) * (-c0)
    s01 = w0 * 0.0 * 0.0 + wi * a0 * a1 + wi * c0 * c1 + wi * (-a0) * (-a1) + wi * (-c0) * (-c1)
    s10 = w0 * 0.0 * 0.0 + wi * a1 * a0 + wi * c1 * c0 + wi * (-a1) * (-a0) + wi * (-c1) * (-c0)
    s11 = w0 * 0.0 * 0.0 + wi * a1 * a1 + wi * c1 * c1 + wi * (-a1) * (-a1) + wi * (-c1) * (-c1)
    return s00, s01, s10, s11


@jit.kernel(inline=True)
def _root(spread: float, a00: float, a10: float, a11: float) -> tuple:
    """The lower Cholesky factor (l00, l10, l11) of ``spread`` · [[a00, ·], [a10, a11]] (its lower triangle, as
    ``ukf.matrix_root`` reads it) and whether it exists (positive definite)."""
    d0 = spread * a00
    if not d0 > 0.0:
        return 0.0, 0.0, 0.0, False
    l00 = math.sqrt(d0)
    l10 = spread * a10 / l00
    d1 = spread * a11 - l10 * l10
    if not d1 > 0.0:
        return 0.0, 0.0, 0.0, False
    return l00, l10, math.sqrt(d1), True


@jit.kernel
def _sigma_rows(kinds: np.ndarray, params: np.ndarray, P_start: np.ndarray, F: np.ndarray, b: np.ndarray) -> tuple:
    """The rows' recursions one after the other (module docstring): coefficients (G, T, 6), the steady frame, the
    last posterior covariances (2, 2, G), and False where a covariance was not positive definite."""
    G, T = kinds.shape
    f00, f01, f10, f11 = F[0, 0], F[0, 1], F[1, 0], F[1, 1]
    b0, b1 = b[0], b[1]
    coef = np.empty((G, T, 6))  # row first: each row's frames contiguous
    P_end = np.empty((2, 2, G))
    settled, repeat_from = 0, 0  # the last kind change, the last frame a row's covariance starts repeating
    for g in range(G):
        sigma_w, sigma_v, alpha, beta, kappa = params[g, 0], params[g, 1], params[g, 2], params[g, 3], params[g, 4]
        spread = alpha * alpha * (2.0 + kappa)  # n + λ = α²(n + κ), n = 2 (ukf.scaled_weights)
        wi = 0.5 / spread
        w0 = (spread - 2.0) / spread + 1.0 - alpha * alpha + beta
        q00, q01, q11 = b0 * b0 * (sigma_w * sigma_w), b0 * b1 * (sigma_w * sigma_w), b1 * b1 * (sigma_w * sigma_w)
        r = sigma_v * sigma_v
        last = settled_from(kinds, g)
        settled = max(settled, last)
        s00, s01, s10, s11 = P_start[0, 0, g], P_start[0, 1, g], P_start[1, 0, g], P_start[1, 1, g]
        p00, p01, p10, p11 = s00, s01, s10, s11
        repeats = T
        for n in range(T):
            k = kinds[g, n]
            l00, l10, l11, definite = _root(spread, p00, p10, p11)
            if not definite:
                return coef, T, P_end, False
            e00, e01, e10, e11 = _covariance(w0, wi, f00 * l00 + f01 * l10, f10 * l00 + f11 * l10, f01 * l11,
                                             f11 * l11)
            n00, n01, n10, n11 = e00 + q00, e01 + q01, e10 + q01, e11 + q11  # P⁻ (eqs. 6–8)
            k0, k1, S = 0.0, 0.0, r  # no measurement: K = 0 (ukf.sigma_update's zero column)
            if k == UPDATE_Y:
                u00, u10, u11, definite = _root(spread, n00, n10, n11)  # sigma points re-drawn from P⁻
                if not definite:
                    return coef, T, P_end, False
                zz, _, zx, _ = _covariance(w0, wi, u00, u10, 0.0, u11)  # Σ W^c dz dz, Σ W^c χ_1 dz (eqs. 9–10)
                S = zz + r
                k0, k1 = zz / S, zx / S  # K = P_xz S⁻¹ (eq. 12)
            cross = 0.5 * ((n01 - k0 * S * k1) + (n10 - k1 * S * k0))  # P⁻ − K S Kᵀ (eq. 11), symmetrised
            n00, n01, n10, n11 = n00 - k0 * S * k0, cross, cross, n11 - k1 * S * k1
            if k <= INIT:  # WAIT / INIT: x = [y, 0] (INIT) or 0 (WAIT), covariance back to the start one
                n00, n01, n10, n11 = s00, s01, s10, s11
                for j in range(4):
                    coef[g, n, j] = 0.0
                coef[g, n, 4], coef[g, n, 5] = 1.0 if k == INIT else 0.0, 0.0
            else:  # [(I − K H) F row-major, K], H = [1, 0]
                coef[g, n, 0], coef[g, n, 1] = f00 - k0 * f00, f01 - k0 * f01
                coef[g, n, 2], coef[g, n, 3] = f10 - k1 * f00, f11 - k1 * f01
                coef[g, n, 4], coef[g, n, 5] = k0, k1
            steady = n00 == p00 and n01 == p01 and n10 == p10 and n11 == p11
            p00, p01, p10, p11 = n00, n01, n10, n11
            if n >= last and steady:  # P_n = P_{n−1} and no kind change later: every later frame repeats frame n
                repeats = n
                repeat_later(coef, g, n)
                break
        repeat_from = max(repeat_from, repeats)
        P_end[0, 0, g], P_end[0, 1, g], P_end[1, 0, g], P_end[1, 1, g] = p00, p01, p10, p11
    return coef, stop_frame(settled, repeat_from, T), P_end, True
