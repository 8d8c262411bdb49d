"""UFIR: the unbiased finite impulse response filter ([PaleRamon-BBox] Alg. 3; [Shmaliy-CMN] Alg. 2 with ψ = 0; notes §1.1–1.2).

Per coordinate channel the horizon holds the N measurements ``y_m … y_n`` (``m = n − N + 1``, oldest first)
of the two-state model ``x_l = F x_{l−1} + B w_l``, ``y_l = H x_l + v_l``. Back-projecting every state to
``x_n`` (backward Euler, notes §1.1, §1.7) stacks them as ``Y = C̄ x_n + noise`` with
``C̄ = [H F^{−(N−1)}; …; H F^{−1}; H]``, and the UFIR estimate is the ordinary least-squares solution

    x̂_n = (C̄ᵀ C̄)⁻¹ C̄ᵀ Y                       (notes §1.1; GNPG G_n = (C̄ᵀ C̄)⁻¹)

which needs no noise statistics (σ_w, σ_v only set the default horizon by the N_opt rule). For the
constant-velocity model this is the least-squares straight line through the last N points: its value and
slope at frame n (:func:`ramp_gain`). :func:`ufir_iterative` is the paper's Kalman-like iterative algorithm,
one output point at a time, used as the reference in the tests and the benchmark.

Implementation (all vectorised over channels; the only Python loops are over a few start-up-length buckets and
the K = 2 state columns): full windows without NaN use the cached gain ``(C̄ᵀC̄)⁻¹C̄ᵀ`` (QR, :func:`ls_gains`)
as an FIR kernel (:mod:`bboxtune.filters.fir_core`); start-up frames use the forward batch form (notes §1.1) whose
normal equations are cumulative sums over frames; full windows with NaN solve their own normal equations, the
clean window's corrected by lag moments of per-frame signals (missing frames, undifferenced rows) — no per-window
gains.

Conventions (shared with :mod:`bboxtune.filters.fir_core`): frame 0 is the first frame; start-up frames n < N − 1 use
all samples so far (growing horizon, "m = 0"); missing samples (NaN) are dropped from the window's least
squares; windows with fewer than 2 valid samples (e.g. frame 0) output the latest valid measurement as
position and velocity 0.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, ClassVar

import numpy as np

from bboxtune.filters import jit
from bboxtune.filters.fir_core import FIRFilter, check_fir_params
from bboxtune.filters.lag_moments import lag_moments, lag_moments_real, lag_polynomial, linear_product
from bboxtune.filters.model import constant_velocity, matrix_powers
from bboxtune.filters.ufir_kernels import ufir_scan


class UFIR(FIRFilter):
    """UFIR filter. Parameters (scalars or per-track (B,) arrays): ``horizon`` N (frames, integer >= 2;
    None → ``rule_horizon(sigma_v, sigma_w, tau, 2)``), ``sigma_w``, ``sigma_v`` (used only by that rule)."""

    name: ClassVar[str] = "ufir"
    DEFAULTS: ClassVar[dict[str, Any]] = {"horizon": None, "sigma_w": 1.0, "sigma_v": 1.0}
    PER_TRACK: ClassVar[tuple[str, ...]] = ("horizon", "sigma_w", "sigma_v")
    GAIN_PARAMS: ClassVar[tuple[str, ...]] = ("horizon",)

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        return check_fir_params(params, self.model)

    def window_gain(self, valid: np.ndarray, params: dict[str, float | int]) -> np.ndarray:
        return self.window_gains(np.asarray(valid, bool)[None], {k: np.array([v]) for k, v in params.items()})[0]

    def window_gains(self, valid: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        L = valid.shape[1]
        axis = self.model.axis()
        if valid.all():  # the gain depends on L only
            return np.broadcast_to(_clean_gain(axis.tau, L), (valid.shape[0], 2, L))
        return ls_gains(back_projected_rows(axis.F, axis.H, L) * valid[:, :, None])

    def _run_frames(self, z: np.ndarray, params: dict[str, Any], positions_only: bool = False) -> np.ndarray:
        """Kernels on: every frame (start-up, full, gappy) by the sliding normal equations of
        :func:`bboxtune.filters.ufir_kernels.ufir_scan`; off: the reference (FFT kernel, :meth:`_startup`, :meth:`_masked`)."""
        if not jit.enabled():
            return super()._run_frames(z, params, positions_only)
        z, X = np.ascontiguousarray(z, dtype=float), np.empty((*z.shape, 2))
        valid = np.isfinite(z)
        horizon, psi = (np.ascontiguousarray(np.broadcast_to(np.asarray(params.get(name, 0.0), dtype=kind), z.shape[:1]))
                        for name, kind in (("horizon", np.int64), ("psi", float)))
        if ufir_scan(z, valid, horizon, psi, X):  # a determined window without a finite estimate
            group, gparams = self._groups(params)
            cs, ns = np.nonzero(np.isnan(X[..., 0]) & np.isnan(X[..., 1]))
            self._check_unobservable(valid, cs, ns, horizon + self.EXTRA_SAMPLES, group, gparams)
            raise FloatingPointError(f"{self.name}: no finite estimate for a window that determines the state")
        return X

    def _startup(self, X: np.ndarray, z: np.ndarray, valid: np.ndarray, holes: np.ndarray, group: np.ndarray,
                 gparams: dict[str, np.ndarray], L_c: np.ndarray) -> None:
        """Start-up frames n < L_c − 1 (rows 0 … n, NaN or not) by the forward batch form referenced to x_0
        (notes §1.1): ``x̂_n = F^n (C_fᵀ C_f)⁻¹ C_fᵀ Z`` with rows ``D_l F^l`` (``H F^l`` for undifferenced
        samples), whose normal equations over frames 0 … n are cumulative sums over l — all frames and
        channels at once, no per-point gains. ``Ψ_l`` as in :func:`ufir_iterative` (ψ = 0 for UFIR).
        Channels are processed in a few buckets of similar start-up length."""
        n_startup = np.minimum(L_c - 1, z.shape[1])
        psi = gparams["psi"][group] if "psi" in gparams else np.zeros(z.shape[0])
        S = int(n_startup[0])
        if (n_startup == S).all():  # one start-up length (e.g. one tuning): a single block
            if S > 0:
                X[:, :S] = self._growing_horizon(z[:, :S], valid[:, :S], psi)
            return
        bucket = np.ceil(np.log2(np.maximum(n_startup, 1))).astype(int)
        for b in np.unique(bucket[n_startup > 0]):
            idx = np.flatnonzero((bucket == b) & (n_startup > 0))
            S = int(n_startup[idx].max())
            X[idx, :S] = np.where(np.arange(S)[None, :, None] < n_startup[idx, None, None],
                                  self._growing_horizon(z[idx, :S], valid[idx, :S], psi[idx]), X[idx, :S])

    def _growing_horizon(self, z: np.ndarray, valid: np.ndarray, psi: np.ndarray) -> np.ndarray:
        """Full-horizon estimates (C, S, 2) from frames 0 … n for every n < S (NaN where unobservable)."""
        f, f_prev = _forward_rows(self.model.tau, z.shape[1])  # rows H F^l and H F^{l−1}
        clean = valid.all()
        if clean:  # Ψ_l = ψ from frame 1 on
            Psi = np.repeat(psi[:, None], z.shape[1], axis=1)
            Psi[:, 0] = 0.0
            Z = z.copy()
            Z[:, 1:] -= Psi[:, 1:] * z[:, :-1]
            r0 = f[:, 0] - Psi * f_prev[:, 0]  # row D_l F^l, first component
            r1 = f[:, 1] - Psi * f_prev[:, 1]
        else:
            plain, diff = row_kinds(valid)
            Psi, Z = differenced(z, diff, psi)
            r0 = valid * (f[None, :, 0] - Psi * f_prev[None, :, 0])
            r1 = valid * (f[None, :, 1] - Psi * f_prev[None, :, 1])
        gram = np.stack([r0 * r0, r0 * r1, r1 * r1, r0 * Z, r1 * Z])
        np.cumsum(gram, axis=2, out=gram)  # C_fᵀ C_f and C_fᵀ Z over rows 0 … n
        x = solve_2x2(gram[0], gram[1], gram[2], gram[3], gram[4])  # x̂_0 from rows 0 … n, (C, S, 2)
        if clean:  # one undifferenced row (frame 0), then differenced ones: determined from n = 1 on
            x[:, 0] = np.nan
        else:
            counts = np.cumsum(np.stack(row_statistics(plain, diff)), axis=2)  # rows 0 … n of each kind
            x[~determined(counts[0], counts[1], counts[2], counts[3], psi[:, None])] = np.nan
        x[..., 0] = x[..., 0] * f[:, 0] + x[..., 1] * f[:, 1]  # x̂_n = F^n x̂_0: position H F^n x̂_0, same velocity
        return x

    def _masked(self, X: np.ndarray, z: np.ndarray, valid: np.ndarray, cs: np.ndarray, ns: np.ndarray,
                L_w: np.ndarray, group: np.ndarray, gparams: dict[str, np.ndarray]) -> None:
        """Full windows holding a NaN (frames (cs, ns)), all at once, as corrections of the clean window. With rows
        ``r_k = h_k − Ψ_{n−k} h_{k+1}`` (``h_k = H F^{−k}``, lag k = n − l < N; a missing sample gives no row, one
        after a missing sample the undifferenced row h_k) a window's normal equations are ``G x = E``,
        ``G = Σ_k r_kᵀ r_k``, ``E = Σ_k r_kᵀ z_{n−k}``. The clean window (every row ``d_k = h_k − ψ h_{k+1}``, data
        read with 0 at missing samples) has the constant ``G_c`` and ``E_c = G_c x_c``, where x_c is the kernel
        estimate already in X. Relative to it a missing frame l removes ``d_kᵀ d_k`` from G and adds
        ``ψ d_kᵀ y_{l−1}`` to E; an undifferenced row adds ``h_kᵀ h_k − d_kᵀ d_k`` to G and ``ψ h_{k+1}ᵀ y_l`` to E.
        For the CV model h_k is linear in k, so each correction is a lag moment Σ_k k^p s_{n−k}, p <= 2, of a
        per-frame signal (:func:`lag_moments`, exact for the 0/1 signals; :func:`lag_moments_real`): no per-window
        gains, no FFT; one pass per channel group (ψ, N), whose coefficients are scalars. Observability is decided
        exactly from the integer moments (row counts and lag sums)."""
        if cs.size == 0:
            return
        channels, row = np.unique(cs, return_inverse=True)
        T = z.shape[1]
        v = valid[channels]
        psi = gparams["psi"][group[channels]] if "psi" in gparams else np.zeros(channels.size)
        plain, diff = row_kinds(v)
        coloured = bool((psi[:, None] * diff).any())  # else ψ = 0 or no differenced row: d_k = h_k
        integer = np.stack([~v, plain] if coloured else [~v]).astype(float)  # missing frame, undifferenced row
        if coloured:
            y0 = np.where(v, z[channels], 0.0)
            real = np.zeros((2, *y0.shape))
            real[0, :, 1:] = ~v[:, 1:] * y0[:, :-1]  # y_{l−1} at missing frames l
            real[1] = plain * y0
        c0, c1 = lag_polynomial(self.model.axis().F, self.model.axis().H)  # h_k = c0 + k c1
        N_of = gparams["horizon"][group[channels]]
        kinds, kind_of = np.unique(np.stack([N_of, psi], axis=1), axis=0, return_inverse=True)
        kind_of = kind_of.reshape(-1)
        for k, (N_val, p) in enumerate(kinds.tolist()):
            N = int(N_val)
            local = np.flatnonzero(kind_of == k)
            G, E = _correction_matrices(c0, c1, N, p, coloured)
            mi = lag_moments(integer[:, local], N, 3).reshape(-1, local.size * T)  # row = power × signal
            x_c = X[channels[local]].reshape(-1, 2).T  # (2, C_g T) kernel estimates of the clean window
            rhs = E[:, :2] @ x_c
            if coloured:
                rhs += E[:, 2:] @ lag_moments_real(real[:, local], N).reshape(-1, local.size * T)
            g = G[:, :1] + G[:, 1:] @ mi
            x = solve_2x2(g[0], g[1], g[2], rhs[0], rhs[1])
            lag_sum = N * (N - 1) / 2
            n_missing, lag_missing = mi[0], mi[integer.shape[0]]
            n_plain = mi[1] if coloured else 0.0
            lag_plain = mi[integer.shape[0] + 1] if coloured else 0.0
            # determined() reads frame sums only through sum_plain − sum_diff with one row of each kind, where the
            # negated lag sums (n − l) give the same difference l_plain − l_diff
            ok = determined(n_plain, N - n_missing - n_plain, -lag_plain, lag_missing + lag_plain - lag_sum, p)
            x[~ok] = np.nan
            mine = np.flatnonzero(kind_of[row] == k) if kinds.shape[0] > 1 else slice(None)
            rank = np.empty(channels.size, np.int64)
            rank[local] = np.arange(local.size) * T
            X[cs[mine], ns[mine]] = x[rank[row[mine]] + ns[mine]]


def _correction_matrices(c0: np.ndarray, c1: np.ndarray, N: int, psi: float,
                         coloured: bool) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of :meth:`UFIR._masked` for windows of N rows with ψ = ``psi``: G (3, 1 + 3S) maps
    [1, lag moments (power-major: p = 0, 1, 2 of each of the S = 1 or 2 signals missing, undifferenced)] to the
    entries 00, 01, 11 of C̄ᵀC̄; E (2, 2 + 4) maps [x_c, lag moments p = 0, 1 of y_{l−1} at missing frames and of y_l
    on undifferenced rows] to C̄ᵀZ (only the first 2 columns without ``coloured``)."""
    h = [(c0[i], c1[i]) for i in range(2)]
    h1 = [(c0[i] + c1[i], c1[i]) for i in range(2)]  # h_{k+1}
    d = [(c0[i] - psi * h1[i][0], (1.0 - psi) * c1[i]) for i in range(2)]  # d_k = h_k − ψ h_{k+1}
    lag_sum = np.array([N, N * (N - 1) / 2, (N - 1) * N * (2 * N - 1) / 6])  # Σ_{k<N} k^p
    S = 2 if coloured else 1
    G = np.zeros((3, 1 + 3 * S))
    clean = np.zeros((2, 2))
    for e, (i, j) in enumerate(((0, 0), (0, 1), (1, 1))):
        dd = np.array(linear_product(d[i], d[j]))
        clean[i, j] = clean[j, i] = G[e, 0] = dd @ lag_sum
        G[e, 1::S] = -dd  # missing frames
        if coloured:
            G[e, 2::S] = np.array(linear_product(h[i], h[j])) - dd  # undifferenced rows
    E = np.zeros((2, 2 + 4 if coloured else 2))
    E[:, :2] = clean
    if coloured:
        for i in range(2):
            E[i, 2::2] = psi * np.array(d[i])
            E[i, 3::2] = psi * np.array(h1[i])
    return G, E


@lru_cache(maxsize=4096)
def _clean_gain(tau: float, L: int) -> np.ndarray:
    """UFIR gain (2, L) of a window of L valid samples (cached per L; read-only)."""
    axis = constant_velocity(tau, ndim=1)
    gain = ls_gains(back_projected_rows(axis.F, axis.H, L)[None])[0]
    gain.setflags(write=False)
    return gain


def back_projected_rows(F: np.ndarray, H: np.ndarray, L: int) -> np.ndarray:
    """``C̄`` (L, K) with row i = ``H F^{−(L−1−i)}`` (oldest sample first, newest row = H): the rows that map
    ``x_n`` to the noiseless measurements of a window ending at n (notes §1.1, backward Euler). Cached per
    (F, H, L); the result is read-only."""
    F = np.asarray(F, dtype=float)
    return _back_projected_rows(F.tobytes(), np.asarray(H, dtype=float)[0].tobytes(), F.shape[0], L)


@lru_cache(maxsize=1024)
def _back_projected_rows(F_bytes: bytes, h_bytes: bytes, K: int, L: int) -> np.ndarray:
    F = np.frombuffer(F_bytes).reshape(K, K)
    F_inv_powers = matrix_powers(np.linalg.inv(F), L)  # F^{−k}, k = 0 … L−1
    rows = np.ascontiguousarray((np.frombuffer(h_bytes) @ F_inv_powers)[::-1])
    rows.setflags(write=False)
    return rows


@lru_cache(maxsize=1024)
def _forward_rows(tau: float, S: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows ``H F^l`` (S, 2) and ``H F^{l−1}`` (S, 2), l = 0 … S−1, of the one-coordinate CV model at
    interval ``tau`` (cached; read-only): the forward batch form of the start-up."""
    axis = constant_velocity(tau, ndim=1)
    f = axis.H[0] @ matrix_powers(axis.F, S)
    f_prev = np.vstack([axis.H @ np.linalg.inv(axis.F), f[:-1]])
    for a in (f, f_prev):
        a.setflags(write=False)
    return f, f_prev


def ls_gains(C: np.ndarray) -> np.ndarray:
    """Least-squares gains ``(CᵀC)⁻¹Cᵀ`` (P, K, L) of P stacked full-column-rank designs C (P, L, K).

    Computed as ``R⁻¹Qᵀ`` from a thin QR factorisation ``C = QR`` (Gram–Schmidt with one
    re-orthogonalisation, vectorised over the P designs; no normal equations). Zero rows of C (missing
    samples) give exactly zero columns of the gain (every step maps a zero entry to zero)."""
    return ls_gains_of_columns([C[:, :, j] for j in range(C.shape[2])])


def ls_gains_of_columns(columns: list[np.ndarray]) -> np.ndarray:
    """:func:`ls_gains` of the design whose K columns are given separately, each (P, L)."""
    K = len(columns)
    P, L = columns[0].shape
    Q: list[np.ndarray] = []  # orthonormal columns, each (P, L)
    R = np.zeros((P, K, K))
    for j in range(K):  # columns of C (K = 2 per coordinate), not taps
        v = np.array(columns[j], dtype=float)
        for _ in range(2):  # Gram–Schmidt twice ("twice is enough")
            for i, q in enumerate(Q):
                coef = np.einsum("pl,pl->p", q, v)
                v -= coef[:, None] * q
                R[:, i, j] += coef
        R[:, j, j] = np.sqrt(np.einsum("pl,pl->p", v, v))
        Q.append(v / R[:, j, j, None])
    gain = np.empty((P, K, L))  # back substitution R W = Qᵀ
    for i in range(K - 1, -1, -1):
        row = Q[i]
        for k in range(i + 1, K):
            row = row - R[:, i, k, None] * gain[:, k]
        np.divide(row, R[:, i, i, None], out=gain[:, i])
    return gain


def ramp_gain(N: int, tau: float) -> np.ndarray:
    """Closed form of the UFIR gain (2, N) for the constant-velocity model (notes §1.1; oldest first):
    position taps ``h_k = [2(2N−1) − 6k] / [N(N+1)]`` and velocity taps ``6(N−1−2k) / [τ N(N²−1)]`` at lag k
    (k = 0 newest) — the value and slope at frame n of the least-squares line. Oracle for the tests."""
    k = np.arange(N)[::-1]
    position = (2.0 * (2 * N - 1) - 6.0 * k) / (N * (N + 1))
    velocity = 6.0 * (N - 1 - 2.0 * k) / (tau * N * (N**2 - 1)) if N > 1 else np.zeros(N)
    return np.stack([position, velocity])


def ufir_iterative(y: np.ndarray, F: np.ndarray, H: np.ndarray, N: int, psi: float = 0.0) -> np.ndarray:
    """Reference: [Shmaliy-CMN] Algorithm 2 (UFIR for CMN; ψ = 0 is the standard UFIR, [PaleRamon-BBox] Alg. 3) run
    literally for every output point n of one track ``y`` (T,) or (T, p) with ``H`` (p, K) — a K-point
    batch start and the G recursion over the horizon. O(N) K×K steps per point: for tests and benchmarks only.

    Horizon of point n: rows l = m … n with ``m = max(0, n − N + 1)`` (start-up: all samples so far).
    Row l uses the differenced measurement ``z_l = y_l − Ψ_l y_{l−1}`` with ``D_l = H − Ψ_l H F⁻¹``, where
    ``Ψ_l = ψ`` if ``y_{l−1}`` is available (l ≥ 1 and finite) and ``Ψ_l = 0`` otherwise (the track's first
    frame and the sample after a gap enter undifferenced). A missing y_l gives no row (prediction only).
    A frame with any NaN counts as missing. The batch start uses the first rows of the horizon that determine
    the state (p = 1 without gaps: K rows, s = m + K − 1); horizons with too few usable rows output
    ``H⁺ y_last`` (position = latest valid y, velocity 0). Returns (T, K)."""
    F = np.asarray(F, dtype=float)
    H = np.atleast_2d(np.asarray(H, dtype=float))
    T = len(y)
    y = np.asarray(y, dtype=float).reshape(T, H.shape[0])
    K = F.shape[0]
    F_inv = np.linalg.inv(F)
    valid = np.all(np.isfinite(y), axis=1)
    Psi = np.where(np.concatenate([[False], valid[:-1]]), psi, 0.0)  # Ψ_l
    out = np.empty((T, K))
    for n in range(T):
        m = max(0, n - N + 1)
        rows = [l for l in range(m, n + 1) if valid[l]]
        start = _batch_start(rows, H, F_inv, Psi)
        if start is None:
            last = np.flatnonzero(valid[: n + 1])
            out[n] = np.linalg.pinv(H) @ (y[last[-1]] if last.size else np.full(H.shape[0], np.nan))
            continue
        s, used, C_ms = start
        Z_ms = np.concatenate([y[l] - Psi[l] * y[l - 1] if Psi[l] else y[l] for l in used])
        G = np.linalg.inv(C_ms.T @ C_ms)  # Alg. 2 line 4: G_s = (C_{m,s}ᵀ C_{m,s})⁻¹
        x = G @ C_ms.T @ Z_ms  # line 5: x̄_s = G_s C_{m,s}ᵀ Y_{m,s} (the z_l of the rows of C_{m,s}, notes §1.3)
        for l in range(s + 1, n + 1):  # line 6
            x = F @ x  # line 11: x̄_l⁻ = F_l x̄_{l−1}
            if not valid[l]:  # missing y_l: no update, G propagates
                G = F @ G @ F.T
                continue
            D = H - Psi[l] * H @ F_inv  # line 7: D_l = H_l − Ψ_l H_{l−1} F_l⁻¹
            z = y[l] - Psi[l] * y[l - 1] if Psi[l] else y[l]  # line 8: z_l = y_l − Ψ_l y_{l−1}
            G = np.linalg.inv(D.T @ D + np.linalg.inv(F @ G @ F.T))  # line 9
            K_l = G @ D.T  # line 10
            x = x + K_l @ (z - D @ x)  # line 12
        out[n] = x  # line 14
    return out


def _batch_start(rows: list[int], H: np.ndarray, F_inv: np.ndarray,
                 Psi: np.ndarray) -> tuple[int, list[int], np.ndarray] | None:
    """The batch-start point s, the frames [m, s] it uses and C_{m,s}: the shortest prefix of ``rows`` with full
    column rank — smallest singular value > 1e-10 × largest after scaling the columns by those of the
    undifferenced rows ``H F^{−(s−l)}`` (so cancellation in ``D_l`` cannot hide a rank loss) — or None if the
    whole horizon is rank deficient."""
    K = F_inv.shape[0]
    for count in range(-(-K // H.shape[0]), len(rows) + 1):  # at least K scalar rows
        used = rows[:count]
        back = [np.linalg.matrix_power(F_inv, used[-1] - l) for l in used]  # F^{−(s−l)}
        C_ms = np.vstack([(H - Psi[l] * H @ F_inv) @ B for l, B in zip(used, back, strict=False)])  # rows D_l F^{−(s−l)}
        scale = np.linalg.norm(np.vstack([H @ B for B in back]), axis=0)
        singular_values = np.linalg.svd(C_ms / scale, compute_uv=False)
        if singular_values[-1] > 1e-10 * singular_values[0]:
            return used[-1], used, C_ms
    return None


def solve_2x2(a: np.ndarray, c: np.ndarray, d: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """Solve stacked symmetric 2×2 systems ``[[a, c], [c, d]] x = [b0, b1]`` in closed form → (..., 2)
    (NaN where the determinant is not positive)."""
    det = a * d - c * c
    ok = det > 0
    out = np.full((*det.shape, 2), np.nan)
    np.divide(d * b0 - c * b1, det, out=out[..., 0], where=ok)
    np.divide(a * b1 - c * b0, det, out=out[..., 1], where=ok)
    return out


def row_kinds(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row kind of each frame l of ``valid`` (..., T): ``plain`` — y_l enters undifferenced (l = 0 or y_{l−1}
    missing), ``diff`` — as ``z_l = y_l − ψ y_{l−1}``. Missing samples are neither."""
    diff = np.zeros_like(valid)
    diff[..., 1:] = valid[..., 1:] & valid[..., :-1]
    return valid & ~diff, diff


def differenced(z: np.ndarray, diff: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Ψ_l`` (C, T) (ψ on differenced rows, else 0) and the row data ``z_l = y_l − Ψ_l y_{l−1}`` (0 where y_l
    is missing) of channels ``z`` (C, T) with per-channel ψ (C,)."""
    y0 = np.where(np.isfinite(z), z, 0.0)
    Psi = psi[:, None] * diff
    Z = y0.copy()
    Z[:, 1:] -= Psi[:, 1:] * y0[:, :-1]
    return Psi, Z


def row_statistics(plain: np.ndarray, diff: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per-frame counts and frame indices of each row kind; summed over a window they feed :func:`determined`."""
    frame = np.arange(plain.shape[-1])
    return plain.astype(float), diff.astype(float), plain * frame, diff * frame


def determined(n_plain: np.ndarray | float, n_diff: np.ndarray | float, sum_plain: np.ndarray | float,
               sum_diff: np.ndarray | float, psi: np.ndarray) -> np.ndarray:
    """True where a window's rows determine the two-state CV state, decided exactly from row counts and frame
    sums. A differenced row at frame l is (1 − ψ)·[1, −τ(n − l − ψ/(1−ψ))] and an undifferenced one
    [1, −τ(n − l)], so two rows are parallel only if one of each has ``l_plain − l_diff = ψ/(1 − ψ)`` (possible for
    ψ = j/(j+1), j >= 2). Hence: at least 2 rows, and not exactly that pair."""
    ratio = psi / (1.0 - psi)
    pair = (n_plain == 1) & (n_diff == 1) & (np.abs(sum_plain - sum_diff - ratio) <= 1e-9 * (1.0 + ratio))
    return (n_plain + n_diff >= 2) & ~pair
