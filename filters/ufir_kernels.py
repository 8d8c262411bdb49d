"""Compiled window scan of the least-squares UFIR family (UFIR, UFIR-CMN): every frame of every channel in one pass.

A window of the UFIR family is the least-squares fit of the rows ``r_k = h_k − Ψ_l h_{k+1}`` (lag k = n − l,
``h_k = H F^{−k} = [1, −k]`` in frame units for the CV model, ``Ψ_l = ψ`` on a differenced row, 0 on an undifferenced
one) to the row data ``z_l = y_l − Ψ_l y_{l−1}`` over the rows l = max(0, n − N + 1) … n ([Shmaliy-CMN] Alg. 2, batch
form; notes §1.1, §1.3). Its normal equations ``G x = E`` only need, per row kind (undifferenced "plain" P,
differenced D), the integer moments Σ 1, Σ k, Σ k² and the data moments Σ z, Σ k z over the window:

    G00 = n_P + (1−ψ)² n_D,     G01 = −k_P − (1−ψ)² k_D + ψ(1−ψ) n_D,
    G11 = k²_P + (1−ψ)² k²_D − 2ψ(1−ψ) k_D + ψ² n_D,
    E0 = s_P + (1−ψ) s_D,       E1 = −t_P − (1−ψ) t_D + ψ s_D,

and every moment slides from frame n − 1 to n in O(1) (all lags grow by one, the row leaving at lag N goes, the new
row enters at lag 0). Start-up windows (frames 0 … n, n < N − 1), full windows and windows with missing samples are
the same formula, so a track with gaps costs what a clean one does. The integer moments are exact; the data moments
are summed afresh every N frames, so their rounding does not grow with T. ``x = G⁻¹ E`` is the estimate of x_n
itself (lag 0): position and velocity per frame. Windows that do not determine the state
(:func:`bboxtune.filters.ufir.determined`) get the latest valid measurement and velocity 0 (NaN before the first one),
as in :mod:`bboxtune.filters.fir_core`.

The numpy references are :meth:`bboxtune.filters.fir_core.FIRFilter._run_frames` with the UFIR overrides
(FFT correlation of the cached gains, :meth:`~bboxtune.filters.ufir.UFIR._growing_horizon`,
:meth:`~bboxtune.filters.ufir.UFIR._masked`).
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit


@jit.kernel
def _determined(n_plain: int, n_diff: int, lag_plain: int, lag_diff: int, ratio: float) -> bool:
    """:func:`bboxtune.filters.ufir.determined` of one window, ``ratio`` = ψ/(1 − ψ) (frame sums = negated lag sums:
    only their difference enters)."""
    pair = n_plain == 1 and n_diff == 1 and abs(lag_diff - lag_plain - ratio) <= 1e-9 * (1.0 + ratio)
    return n_plain + n_diff >= 2 and not pair


@jit.kernel
def ufir_scan(z: np.ndarray, valid: np.ndarray, horizon: np.ndarray, psi: np.ndarray, X: np.ndarray) -> int:
    """Estimates X (C, T, 2) of channels ``z`` (C, T) (``valid`` (C, T) bool; per channel ``horizon`` N (C,) int64 rows
    and ``psi`` (C,), 0 for UFIR) in frame units. Returns the number of windows that determine the state but whose
    solution is not finite (left NaN; the caller reports them)."""
    C, T = z.shape
    failures = 0
    kind = np.empty(T, np.int8)  # row kind of each frame: 0 none (missing), 1 undifferenced, 2 differenced
    row = np.empty(T)  # row data z_l: y_l, or y_l − ψ y_{l−1}
    for c in range(C):
        N = horizon[c]
        p = psi[c]
        q = 1.0 - p
        q2 = q * q
        ratio = p / q
        for l in range(T):
            kind[l] = 0 if not valid[c, l] else (2 if l > 0 and valid[c, l - 1] else 1)
            row[l] = z[c, l] - p * z[c, l - 1] if kind[l] == 2 else z[c, l]
        nP = nD = kP = kD = k2P = k2D = 0  # integer moments of each row kind
        sP = sD = tP = tD = 0.0  # data moments Σ z, Σ k z of each row kind
        last = np.nan
        for n in range(T):
            # every row's lag grows by one
            k2P += 2 * kP + nP
            k2D += 2 * kD + nD
            kP += nP
            kD += nD
            tP += sP
            tD += sD
            old = n - N  # the row leaving the window (lag N)
            if old >= 0 and kind[old] == 2:
                nD -= 1
                kD -= N
                k2D -= N * N
                sD -= row[old]
                tD -= N * row[old]
            elif old >= 0 and kind[old] == 1:
                nP -= 1
                kP -= N
                k2P -= N * N
                sP -= row[old]
                tP -= N * row[old]
            if kind[n] == 2:  # the new row, lag 0
                nD += 1
                sD += row[n]
            elif kind[n] == 1:
                nP += 1
                sP += row[n]
            if kind[n]:
                last = z[c, n]
            if n % N == N - 1:  # data moments afresh: rounding bounded by N steps
                sP = sD = tP = tD = 0.0
                for l in range(n - N + 1, n + 1):
                    if kind[l] == 2:
                        sD += row[l]
                        tD += (n - l) * row[l]
                    elif kind[l] == 1:
                        sP += row[l]
                        tP += (n - l) * row[l]
            if not _determined(nP, nD, kP, kD, ratio):
                X[c, n, 0] = last
                X[c, n, 1] = 0.0 if last == last else np.nan
                continue
            g00 = nP + q2 * nD
            g01 = -kP - q2 * kD + p * q * nD
            g11 = k2P + q2 * k2D - 2.0 * p * q * kD + p * p * nD
            e0 = sP + q * sD
            e1 = -tP - q * tD + p * sD
            det = g00 * g11 - g01 * g01
            if det > 0.0:
                inv = 1.0 / det
                X[c, n, 0] = (g11 * e0 - g01 * e1) * inv
                X[c, n, 1] = (g00 * e1 - g01 * e0) * inv
            if not (det > 0.0 and np.isfinite(X[c, n, 0]) and np.isfinite(X[c, n, 1])):
                X[c, n, 0] = X[c, n, 1] = np.nan
                failures += 1
    return failures
