"""OUFIR: the optimal unbiased (minimum-variance unbiased) FIR filter ([PaleRamon-BBox] Alg. 4; notes §1.6).

Per coordinate channel a window holds the L raw samples ``y_m … y_n`` (oldest first, ``m = n − L + 1``) of the
two-state model ``x_l = F x_{l−1} + B w_l``, ``y_l = H x_l + v_l``, ``w ~ N(0, σ_w²)`` (acceleration),
``v ~ N(0, σ_v²)``. Forward-stacked from the horizon start (notes §1.1, §1.5)::

    Y = C_f x_m + G_w W + V,      x_n = F^{L−1} x_m + D_w W,      W = [w_{m+1} … w_n]ᵀ

OUFIR is the linear estimate of x_n with the least error covariance among those unbiased for every x_m
(``K C_f = F^{L−1}``); it needs no prior and is the same estimator as Kwon's FIR (:mod:`bboxtune.filters.fir`), the ML FIR,
and the OFIR with an infinitely wide prior. Only the ratio σ_w/σ_v enters the gain.

Conventions: missing samples (``valid`` False) are dropped from Y, C_f and G_w (the process noise of every step
stays), so a window with gaps gives the exact OUFIR of its observed samples. Start-up windows (frames 0 … n,
n < N − 1) give the full-horizon OUFIR on the samples so far ([PaleRamon-BBox] Alg. 4, "m = 0 otherwise"); a window with
fewer than 2 valid samples outputs the latest valid measurement with velocity 0 (:mod:`bboxtune.filters.fir_core`).
Clean full windows apply the batch gain :func:`oufir_gain` as a kernel; start-up frames and windows holding a NaN
use the same estimator in its recursive form (K-point UFIR start + KF, or the associative composition of
:mod:`bboxtune.filters.window_scan` for windows holding a NaN; :class:`KalmanWindowFIR`), run on the data.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, ClassVar

import numpy as np
import scipy.linalg as sla

from bboxtune.filters import jit
from bboxtune.filters.fir_core import FIRFilter, check_fir_params, correlate
from bboxtune.filters.model import matrix_powers
from bboxtune.filters.window_scan import DATA, STRUCTURE, BlockLayout, FrameModel, window_estimates
from bboxtune.filters.window_scan_kernels import scan_channels

SCAN_SAMPLES = 1 << 18  # channel-frames per batch of the window scan (3 arrays of 14 floats each: ~90 MB)
COND_MAX = 1e8  # bound on cond(Ψ_Y/σ_v²) above which the ML least-squares form replaces the Cholesky form



def window_model(F: np.ndarray, H: np.ndarray, B: np.ndarray, L: int) -> tuple[np.ndarray, ...]:
    """Forward-stacked window of L samples, scalar measurement and scalar noise input (unit σ_w).

    Returns ``F^{L−1}`` (K, K); ``C_f`` (L, K), rows ``H F^i`` (notes §1.1); ``G_w`` (L, L−1),
    ``G_w[i, j−1] = H F^{i−j} B`` for j ≤ i, the coefficient of w_{m+j} in y_{m+i}; ``D_w`` (K, L−1), columns
    ``F^{L−1−j} B``, the coefficient of w_{m+j} in x_n (notes §1.5)."""
    F_pow = matrix_powers(F, L)
    C_f = (H @ F_pow)[:, 0, :]
    h = (H @ F_pow @ B)[:, 0, 0]  # Markov parameters h_k = H F^k B
    G_w = sla.toeplitz(np.concatenate([[0.0], h[:-1]]), np.zeros(L - 1))  # constant along diagonals i − j
    D_w = (F_pow[::-1][1:] @ B)[:, :, 0].T
    return F_pow[-1], C_f, G_w, D_w


def window_gls_gain(F: np.ndarray, H: np.ndarray, B: np.ndarray, valid: np.ndarray, ratio: float,
                    P_prior: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Gains of the best linear unbiased estimate ``x̂_n = W_y @ Y + W_x @ x̄_m`` on one window.

    ``valid`` (L,) marks the samples used; ``ratio`` = σ_w/σ_v; ``P_prior`` (K, K) = covariance of a prior
    ``x_m ~ (x̄_m, P_prior)`` in units of σ_v² (None: no prior, i.e. OUFIR, and ``W_x = 0``). Returns
    ``W_y`` (K, L), zero at invalid samples, and ``W_x`` (K, K).

    With ``Ψ = Ψ_Y/σ_v² = I + ratio² G_w G_wᵀ`` and prior information ``J = P_prior⁻¹`` (notes §1.5–1.6)::

        x̂_m = (C_fᵀ Ψ⁻¹ C_f + J)⁻¹ (C_fᵀ Ψ⁻¹ Y + J x̄_m)
        x̂_n = F^{L−1} x̂_m + ratio² D_w G_wᵀ Ψ⁻¹ (Y − C_f x̂_m)

    which for J = 0 is ``K_OUFIR = F^{L−1} Ω C_fᵀ Ψ⁻¹ + D_w Q̄ G_wᵀ Ψ⁻¹ (I − C_f Ω C_fᵀ Ψ⁻¹)``. Ψ is whitened by
    its Cholesky factor; when ``1 + ratio² ‖G_w‖²_F > COND_MAX`` (process noise ≫ measurement noise over a long
    window) the same estimate is taken from the equivalent ML least squares over (x_m, W), solved by QR."""
    L = valid.size
    K = F.shape[0]
    F_last, C_f, G_w, D_w = window_model(F, H, B, L)
    idx = np.flatnonzero(valid)
    C, G = C_f[idx], G_w[idx]
    J_half = np.zeros((0, K)) if P_prior is None else sla.solve_triangular(  # J = J_halfᵀ J_half
        np.linalg.cholesky(P_prior), np.eye(K), lower=True)
    W_y = np.zeros((K, L))
    if 1.0 + ratio**2 * np.sum(G**2) <= COND_MAX:
        Psi = sla.blas.dsyrk(ratio**2, G, lower=1)  # lower triangle of ratio² G_w G_wᵀ
        Psi[np.diag_indices_from(Psi)] += 1.0
        root = sla.cholesky(Psi, lower=True, check_finite=False)  # Ψ = root rootᵀ (reads the lower triangle)
        A = sla.solve_triangular(root, C, lower=True)  # whitened C_f
        S = sla.solve_triangular(root, G @ D_w.T, lower=True)  # whitened G_w D_wᵀ
        Q, R = np.linalg.qr(np.vstack([A, J_half]))
        Q_y, Q_p = Q[: idx.size], Q[idx.size:]
        core = F_last @ sla.solve_triangular(R, Q_y.T) + ratio**2 * (S - Q_y @ (Q_y.T @ S)).T
        W_y[:, idx] = sla.solve_triangular(root, core.T, lower=True, trans=1).T
        W_x = (F_last - ratio**2 * S.T @ A) @ sla.solve_triangular(R, Q_p.T @ J_half)
        return W_y, W_x
    # ML form: minimise ‖J_half (x_m − x̄_m)‖² + ‖Y − C_f x_m − G_w W‖² + ‖W‖²/ratio², then x̂_n = [F^{L−1}, D_w] θ̂
    n_p = J_half.shape[0]
    M = np.zeros((n_p + idx.size + L - 1, K + L - 1))
    M[:n_p, :K] = J_half
    M[n_p: n_p + idx.size] = np.hstack([C, G])
    M[n_p + idx.size:, K:] = np.eye(L - 1) / ratio
    scale = np.linalg.norm(M, axis=0)
    Q, R = np.linalg.qr(M / scale)
    gain = sla.solve_triangular(R, (np.hstack([F_last, D_w]) / scale).T, trans=1).T @ Q.T
    W_y[:, idx] = gain[:, n_p: n_p + idx.size]
    return W_y, gain[:, :n_p] @ J_half


def oufir_gain(F: np.ndarray, H: np.ndarray, B: np.ndarray, valid: np.ndarray, sigma_w: float,
               sigma_v: float) -> np.ndarray:
    """OUFIR gain (K, L) of one window (notes §1.6; the batch form of [PaleRamon-BBox] Alg. 4)."""
    return window_gls_gain(F, H, B, np.asarray(valid, bool), sigma_w / sigma_v)[0]


def ufir_init(F: np.ndarray, H: np.ndarray, B: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, ...]:
    """K-point UFIR start of Alg. 4 (notes §1.2, §1.6) from K samples at ``offsets`` (frames relative to the
    last one, s = 0, e.g. [−1, 0]): ``x̂_s = C_s⁻¹ Y_s`` with rows ``C_s = H F^{−(s−i)}``. Returns ``C_s⁻¹``
    and the two parts of its error covariance, ``P_s = σ_v² P_v + σ_w² P_w`` (process noise between the samples:
    ``y_i = H F^{i−s} x_s − Σ_{i<j≤s} H F^{i−j} B w_j + v_i``)."""
    offsets = np.asarray(offsets)
    F_inv = np.linalg.inv(F)  # exact for the CV model (det F = 1)
    back = matrix_powers(F_inv, int(-offsets.min()) + 1)  # F^0, F^−1, …
    C_s = (H @ back[-offsets])[:, 0, :]
    noise_steps = np.arange(offsets.min() + 1, 1)  # frames j of the w_j between the first sample and s
    lag = noise_steps[None, :] - offsets[:, None]  # j − i > 0 where w_j enters y_i
    G_bar = np.where(lag > 0, -(H @ back[np.maximum(lag, 0)] @ B)[..., 0, 0], 0.0)
    C_inv = np.linalg.inv(C_s)
    return C_inv, C_inv @ C_inv.T, C_inv @ G_bar @ G_bar.T @ C_inv.T


def kf_step(x: np.ndarray, P: np.ndarray, y: float, F: np.ndarray, H: np.ndarray, Q: np.ndarray,
            R: float) -> tuple[np.ndarray, np.ndarray]:
    """One step of [PaleRamon-BBox] Alg. 1 (notes §1.0): predict, then update with ``y`` unless it is NaN (Joseph form)."""
    x, P = F @ x, F @ P @ F.T + Q
    if np.isnan(y):
        return x, P
    S = (H @ P @ H.T)[0, 0] + R
    K = P @ H.T / S
    x = x + K[:, 0] * (y - (H @ x)[0])
    I_KH = np.eye(x.size) - K @ H
    return x, I_KH @ P @ I_KH.T + R * (K @ K.T)


def hold_last(y: np.ndarray, n: int) -> np.ndarray:
    """Unobservable-window output at frame n: latest finite y at or before n, velocity 0 (NaN if none)."""
    seen = np.flatnonzero(np.isfinite(y[: n + 1]))
    return np.array([y[seen[-1]], 0.0]) if seen.size else np.full(2, np.nan)


def oufir_iterative(y: np.ndarray, F: np.ndarray, H: np.ndarray, B: np.ndarray, horizon: int, sigma_w: float,
                    sigma_v: float) -> np.ndarray:
    """[PaleRamon-BBox] Alg. 4 literally, one output at a time, for one channel ``y`` (T,) (NaN = missing) → (T, K).

    At each n: window m = max(0, n − N + 1) … n; start from the K-point UFIR estimate on the first K valid
    samples of the window with its exact error covariance P_s (notes §1.6), then run the KF (Alg. 1) to n.
    Fewer than K valid samples in the window: :func:`hold_last`."""
    K = F.shape[0]
    Q = sigma_w**2 * B @ B.T
    out = np.empty((y.size, K))
    for n in range(y.size):
        idx = np.flatnonzero(np.isfinite(y[max(0, n - horizon + 1): n + 1])) + max(0, n - horizon + 1)
        if idx.size < K:
            out[n] = hold_last(y, n)
            continue
        s = idx[K - 1]
        C_inv, P_v, P_w = ufir_init(F, H, B, idx[:K] - s)
        x, P = C_inv @ y[idx[:K]], sigma_v**2 * P_v + sigma_w**2 * P_w
        for l in range(s + 1, n + 1):
            x, P = kf_step(x, P, y[l], F, H, Q, sigma_v**2)
        out[n] = x
    return out


class KalmanWindowFIR(FIRFilter):
    """A FIR back end whose window estimate is also a KF (Alg. 1) run over the window from a start state built from
    the window's first valid sample(s) — OUFIR (Alg. 4) and OFIR (Alg. 2).

    Clean full windows use the batch gain :meth:`window_gain` (cached, applied as a kernel). Start-up frames (the
    growing window 0 … n) run that recursion on the data, all channels at once (NaN = predict only): exact, no O(L³)
    gain per start-up point. Full windows holding a NaN (95 % of them with 5 % missing frames and N = 60) compose
    per-frame elements associatively (:mod:`bboxtune.filters.window_scan`: O(1) 2×2 compositions per output whatever
    L, equal to the per-window KF to ~1e-13). Data are scaled by σ_v (R = 1, Q = (σ_w/σ_v)² B Bᵀ). A window with
    fewer than 2 valid samples gives NaN here (fir_core's fallback). The compiled path: :meth:`_run_frames`."""

    START_COUNT: ClassVar[int]  # valid samples the start state consumes
    SPLIT_TRACKS = False  # the window scan splits its own channel groups; split tracks too: ~20 % slower in the vec env
    PRIOR_AT_START: ClassVar[bool] = False  # the KF starts after the oldest valid sample a from [y_a, 0], P0 (OFIR)
    CHUNK: ClassVar[int] = 65_536  # windows per vectorised batch of :meth:`_kalman_windows` (bounds memory)

    @abstractmethod
    def start_state(self, y_first: np.ndarray, y_now: np.ndarray, gap: np.ndarray,
                    params: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Start states of P windows at the sample completing START_COUNT valid ones: ``y_first``, ``y_now`` (P,)
        the first valid and the current sample (scaled by σ_v), ``gap`` (P,) frames between them; ``params``
        arrays (P,). Returns x (P, K) and its error covariance (P, K, K), both in units of σ_v."""

    def _run_frames(self, z: np.ndarray, params: dict[str, Any], positions_only: bool = False) -> np.ndarray:
        """Kernels on: channels without a missing sample take their full windows from the FFT kernel and their start-up
        frames from :func:`bboxtune.filters.window_scan_kernels.scan_channels`; channels with a missing sample take
        every frame from the scan (with 5 % of frames missing and N = 60, 95 % of the windows hold a gap: their FFT
        estimates would be overwritten). Off: the reference (FFT kernel, :meth:`_startup`, :meth:`_masked`)."""
        if not jit.enabled():
            return super()._run_frames(z, params, positions_only)
        valid = np.isfinite(z)
        group, gparams = self._groups(params)
        L_c = (gparams["horizon"] + self.EXTRA_SAMPLES)[group]  # (C,) window length of each channel
        gappy = ~valid.all(axis=1)
        X = self._clean_full_windows(z, gappy, group, gparams, positions_only)
        sv = gparams["sigma_v"][group].astype(float)
        P0 = self.scaled_prior(sv) if self.PRIOR_AT_START else np.zeros((sv.size, 2, 2))  # type: ignore[attr-defined]
        axis = self.model.axis()
        if scan_channels(X, z, valid, gappy, group, L_c, (gparams["sigma_w"][group] / sv) ** 2, sv, self.PRIOR_AT_START,
                         P0, axis.F, axis.B[:, 0]):  # a window without a finite estimate: reported
            return self._fallback(X, z, valid, L_c, group, gparams)
        return X

    def _clean_full_windows(self, z: np.ndarray, gappy: np.ndarray, group: np.ndarray, gparams: dict[str, np.ndarray],
                            positions_only: bool) -> np.ndarray:
        """X (C, T, 2) holding the FFT kernel's estimates of the full windows of the channels that are not ``gappy``
        (their velocities NaN with ``positions_only``); every other entry is left for the scan to write."""
        C, T = z.shape
        if gappy.all():
            return np.empty((C, T, 2))
        clean = slice(None) if not gappy.any() else np.flatnonzero(~gappy)
        used, local = np.unique(group[clean], return_inverse=True)  # only the gains the clean channels apply
        W = self._full_gains({name: v[used] for name, v in gparams.items()}, T)
        out = correlate(z[clean], W[:, :1] if positions_only else W, local.reshape(-1), wrap=True)
        if isinstance(clean, slice) and not positions_only:
            return np.ascontiguousarray(out)
        X = np.empty((C, T, 2))
        X[clean, :, :out.shape[2]] = out
        if positions_only:
            X[clean, :, 1] = np.nan
        return X

    def _startup(self, X: np.ndarray, z: np.ndarray, valid: np.ndarray, holes: np.ndarray, group: np.ndarray,
                 gparams: dict[str, np.ndarray], L_c: np.ndarray) -> None:
        last = np.minimum(L_c - 2, z.shape[1] - 1)  # start-up frames 0 … L_c − 2
        cs = np.flatnonzero(last >= 0)
        self._kalman_windows(X, z, valid, cs, np.zeros(cs.size, np.int64), np.zeros(cs.size, np.int64), last[cs],
                             {k: v[group[cs]] for k, v in gparams.items()})

    def scan_start(self, y: np.ndarray, valid: np.ndarray, channel: np.ndarray, first: np.ndarray,
                   params: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """How the KF over windows starting at frame ``first`` (P,) of channels ``channel`` (P,) begins, for
        :mod:`bboxtune.filters.window_scan`: the first frame whose element the window composes, and the prior mean (k, P, 2)
        and covariance (P, 2, 2) of the state before it (None: a flat prior). ``y`` (k, C', T) scaled by σ_v (k
        channels sharing the missing frames ``valid`` (C', T)), ``params`` arrays (P,). Default: flat prior before
        the window (OUFIR)."""
        return first, None, None

    def _masked(self, X: np.ndarray, z: np.ndarray, valid: np.ndarray, cs: np.ndarray, ns: np.ndarray,
                L_w: np.ndarray, group: np.ndarray, gparams: dict[str, np.ndarray]) -> None:
        """Full windows holding a NaN (frames (cs, ns), lengths L_w = horizon + EXTRA_SAMPLES), all at once by the
        associative scan of :mod:`bboxtune.filters.window_scan` (O(1) compositions per window, whatever L), in batches of
        channels. Channels with the same gain parameters, missing frames and requested windows (e.g. the four
        coordinates of a box track) share one scan: A, C and J are composed once, their b and η side by side
        (:class:`bboxtune.filters.window_scan.Elements`). The rare window the scan cannot form from one prefix and one
        suffix runs its own KF (:meth:`_kalman_windows`)."""
        if cs.size == 0:
            return
        if np.any(L_w != gparams["horizon"][group[cs]] + self.EXTRA_SAMPLES):
            raise ValueError(f"{self.name}: the window scan takes full windows only (L_w = horizon + "
                             f"{self.EXTRA_SAMPLES}); start-up windows run the KF of _startup")
        T = z.shape[1]
        channels, local = np.unique(cs, return_inverse=True)
        wanted = np.zeros((channels.size, T), bool)
        wanted[local, ns] = True
        key = np.hstack([group[channels].astype(np.int64)[:, None].view(np.uint8),
                         np.packbits(valid[channels], axis=1), np.packbits(wanted, axis=1)])
        _, kind, size = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        order = np.argsort(kind.reshape(-1), kind="stable")  # channels of one kind together
        offset = np.cumsum(size) - size
        axis = self.model.axis()
        step = max(1, SCAN_SAMPLES // T)
        for k in np.unique(size).tolist():  # kinds of k channels each
            members = order[offset[size == k][:, None] + np.arange(k)]  # (R, k) indices into channels
            E = min(step, members.shape[0]) * T
            work = (np.empty((2, len(STRUCTURE), E)), np.empty((2, len(DATA), k, E)))  # prefix and suffix
            for part in (members[i:i + step] for i in range(0, members.shape[0], step)):
                self._scan_batch(X, z, valid, channels[part], wanted[part[:, 0]], group, gparams, axis, work)

    def _scan_batch(self, X: np.ndarray, z: np.ndarray, valid: np.ndarray, members: np.ndarray, wanted: np.ndarray,
                    group: np.ndarray, gparams: dict[str, np.ndarray], axis: Any,
                    work: tuple[np.ndarray, np.ndarray]) -> None:
        """:meth:`_masked` for R kinds of k channels ``members`` (R, k) sharing parameters and missing frames, at the
        frames ``wanted`` (R, T)."""
        T = z.shape[1]
        rep = members[:, 0]
        per = {name: v[group[rep]] for name, v in gparams.items()}
        L = per["horizon"] + self.EXTRA_SAMPLES  # one window length per channel: the block length of its scan
        sv = per["sigma_v"]
        q = (per["sigma_w"] / sv) ** 2  # Q = (σ_w/σ_v)² B Bᵀ in units of σ_v
        y, v = z[members.T] / sv[:, None], valid[rep]  # y (k, R, T)
        layout = BlockLayout(L, T)
        c, t = layout.channel, layout.frame
        prefix, suffix = layout.scans(FrameModel(axis.F, axis.B[:, 0], q[c], y[:, c, t], v[c, t]), work)
        r, n = np.nonzero(wanted)
        first = n - L[r] + 1
        counts = np.concatenate([np.zeros((rep.size, 1), np.int64), np.cumsum(v, axis=1)], axis=1)
        ok = counts[r, n + 1] - counts[r, first] >= 2  # fewer than 2 valid samples: NaN (fir_core's fallback)
        lo, mean, cov = self.scan_start(y, v, r[ok], first[ok], {name: a[r[ok]] for name, a in per.items()})
        est = np.full((members.shape[1], r.size, 2), np.nan)
        est[:, ok], inside = window_estimates(layout, prefix, suffix, L, r[ok], lo, n[ok], mean, cov)
        X[members[r].T, n] = est * sv[r, None]
        if inside.any():
            odd = np.flatnonzero(ok)[inside]
            cs, ns = members[r[odd]].ravel(), np.repeat(n[odd], members.shape[1])
            self._kalman_windows(X, z, valid, cs, ns - L[r[odd]].repeat(members.shape[1]) + 1, ns, ns,
                                 {name: a[group[cs]] for name, a in gparams.items()})

    def _kalman_windows(self, X: np.ndarray, z: np.ndarray, valid: np.ndarray, cs: np.ndarray, first: np.ndarray,
                        emit: np.ndarray, last: np.ndarray, params: dict[str, np.ndarray]) -> None:
        """For windows p (channel cs[p], frames first[p] … last[p]): run the KF from the start state and write
        X[cs[p], t] for emit[p] <= t <= last[p] (NaN while fewer than 2 valid samples)."""
        order = np.argsort(first - last, kind="stable")  # longest first: the windows still running form a prefix
        for chunk in np.array_split(order, max(1, -(-order.size // self.CHUNK))):
            self._kalman_chunk(X, z, valid, cs[chunk], first[chunk], emit[chunk], last[chunk],
                               {k: v[chunk] for k, v in params.items()})

    def _kalman_chunk(self, X: np.ndarray, z: np.ndarray, valid: np.ndarray, cs: np.ndarray, first: np.ndarray,
                      emit: np.ndarray, last: np.ndarray, params: dict[str, np.ndarray]) -> None:
        """:func:`kf_step` written out entry by entry for the two-state axis model (H = [1, 0]), on arrays of
        windows: x = (x0, x1), symmetric P = (p00, p01, p11); the gain is 0 at missing samples."""
        axis = self.model.axis()
        (f00, f01), (f10, f11) = axis.F.tolist()
        BBt = axis.B @ axis.B.T
        ratio2 = (params["sigma_w"] / params["sigma_v"]) ** 2
        q00, q01, q11 = ratio2 * BBt[0, 0], ratio2 * BBt[0, 1], ratio2 * BBt[1, 1]
        x0, x1, p00, p01, p11 = (np.zeros(cs.size) for _ in range(5))
        count = np.zeros(cs.size, np.int64)
        y_first = np.zeros(cs.size)
        t_first = np.zeros(cs.size, np.int64)
        span = last - first + 1
        for i in range(int(span.max()) if span.size else 0):  # loop over window time, vectorised over windows
            a = int(np.searchsorted(-span, -i, side="left"))  # windows still running form a prefix
            t = first[:a] + i
            ok = valid[cs[:a], t]
            y = np.where(ok, z[cs[:a], t], 0.0) / params["sigma_v"][:a]
            x0[:a], x1[:a] = f00 * x0[:a] + f01 * x1[:a], f10 * x0[:a] + f11 * x1[:a]  # predict
            r0, r1 = f00 * p00[:a] + f01 * p01[:a], f00 * p01[:a] + f01 * p11[:a]  # first row of F P
            s0, s1 = f10 * p00[:a] + f11 * p01[:a], f10 * p01[:a] + f11 * p11[:a]  # second row of F P
            P00, P01, P11 = r0 * f00 + r1 * f01 + q00[:a], r0 * f10 + r1 * f11 + q01[:a], s0 * f10 + s1 * f11 + q11[:a]
            k0, k1 = ok * P00 / (P00 + 1.0), ok * P01 / (P00 + 1.0)  # K = P Hᵀ / (H P Hᵀ + R)
            e = y - x0[:a]
            x0[:a] += k0 * e
            x1[:a] += k1 * e
            p00[:a] = (1.0 - k0) ** 2 * P00 + k0**2  # Joseph form (I − KH) P (I − KH)ᵀ + K R Kᵀ
            p01[:a] = (1.0 - k0) * (P01 - k1 * P00) + k0 * k1
            p11[:a] = P11 - 2.0 * k1 * P01 + k1**2 * (P00 + 1.0)
            count[:a] += ok
            fresh = np.flatnonzero(ok & (count[:a] == 1))
            y_first[fresh], t_first[fresh] = y[fresh], t[fresh]
            start = np.flatnonzero(ok & (count[:a] == self.START_COUNT))
            if start.size:
                x, P = self.start_state(y_first[start], y[start], t[start] - t_first[start],
                                        {k: v[start] for k, v in params.items()})
                x0[start], x1[start] = x[:, 0], x[:, 1]
                p00[start], p01[start], p11[start] = P[:, 0, 0], P[:, 0, 1], P[:, 1, 1]
            out = np.flatnonzero(t >= emit[:a])
            X[cs[out], t[out]] = np.where((count[out] >= 2)[:, None], np.stack([x0[out], x1[out]], axis=1)
                                          * params["sigma_v"][out, None], np.nan)


class OUFIR(KalmanWindowFIR):
    """Optimal unbiased FIR filter ([PaleRamon-BBox] Alg. 4): minimum-variance unbiased over the last N frames.

    Parameters (all per track: scalar or (B,)): ``sigma_w`` (acceleration noise std, units/s²), ``sigma_v``
    (measurement noise std, units), ``horizon`` N (integer >= 2; None → :func:`bboxtune.filters.horizon.rule_horizon`).
    Only σ_w/σ_v shapes the gain; σ_v alone does not change the estimate.

    >>> import numpy as np
    >>> from bboxtune import filters
    >>> f = filters.make("oufir", filters.constant_velocity(0.05), sigma_w=50.0, sigma_v=4.0, horizon=20)
    >>> bool(np.allclose(f.run(np.arange(30.0)[:, None])[-1], [29.0, 20.0]))  # a ramp is reproduced exactly
    True
    """

    name = "oufir"
    DEFAULTS: ClassVar[dict[str, Any]] = {"sigma_w": 1.0, "sigma_v": 1.0, "horizon": None}
    PER_TRACK: ClassVar[tuple[str, ...]] = ("horizon", "sigma_w", "sigma_v")
    START_COUNT = 2

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        return check_fir_params(params, self.model)

    def window_gain(self, valid: np.ndarray, params: dict[str, float | int]) -> np.ndarray:
        axis = self.model.axis()
        return oufir_gain(axis.F, axis.H, axis.B, valid, params["sigma_w"], params["sigma_v"])

    def start_state(self, y_first: np.ndarray, y_now: np.ndarray, gap: np.ndarray,
                    params: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The K-point (K = 2) UFIR start on the first two valid samples with its exact error covariance."""
        axis = self.model.axis()
        x, P = np.empty((gap.size, 2)), np.empty((gap.size, 2, 2))
        ratio = params["sigma_w"] / params["sigma_v"]
        for d in np.unique(gap):
            rows = np.flatnonzero(gap == d)
            C_inv, P_v, P_w = ufir_init(axis.F, axis.H, axis.B, np.array([-d, 0]))
            x[rows] = np.stack([y_first[rows], y_now[rows]], axis=1) @ C_inv.T
            P[rows] = P_v + ratio[rows, None, None] ** 2 * P_w
        return x, P
