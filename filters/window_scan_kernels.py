"""Compiled window scan of the window-KF FIR back ends (OUFIR, OFIR, Kwon's FIR): their start-up windows and the
windows holding a missing sample, all frames of a channel group in one pass.

The per-frame elements and the associative composition of :mod:`bboxtune.filters.window_scan` (Särkkä &
García-Fernández, IEEE TAC 2021, Lemmas 7–8), written out per frame: the rank-one single-frame forms
(``FrameModel.append``, ``FrameModel.prepend``) and the general ``combine`` without its covariance rows. Frames are
cut into blocks of the window length L with prefix (block start … t) and suffix (t … block end) compositions; a
window [lo, n] is one suffix then one prefix, one prefix (lo at a block start) or one suffix (n at a block end), and
a window inside one block touching neither end is composed frame by frame. Start-up windows (n < L − 1) all start
at the track's first frames: one running composition. The estimate is ``flat_prior_estimate`` (OUFIR, Kwon: lo = the
window's first frame) or ``prior_estimate`` with the prior [y_a, 0], P0 at the window's oldest valid sample a (OFIR:
lo = a + 1). Windows with fewer than 2 valid samples are left NaN (fir_core's fallback).

A composition is stored as its structure rows S[i] = A00 A01 A10 A11 C00 C01 C11 J00 J01 J11, shared by the k
channels of a group (same missing frames and parameters: the coordinates of a box), and its data rows
D[i, m] = b0 b1 η0 η1 of channel m. The helpers are inlined into the kernel (``jit.kernel(inline=True)``: numba IR inlining,
~30 % faster here than calls; ~7 s more to compile). The numpy references are
:meth:`bboxtune.filters.oufir.KalmanWindowFIR._startup` and :meth:`~bboxtune.filters.oufir.KalmanWindowFIR._masked`
(``$BBOXTUNE_JIT=0``).
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit


@jit.kernel(inline=True)
def _element(F: np.ndarray, B: np.ndarray, fr: np.ndarray, y: np.ndarray, t: int, S: np.ndarray, D: np.ndarray,
             i: int) -> None:
    """A = F − β B f, b = β y B, C = c B Bᵀ, η = w y fᵀ, J = w fᵀ f (f = H F; y (k,) the frame's samples)."""
    w, c, beta = fr[t, 0], fr[t, 1], fr[t, 2]
    f0, f1 = F[0, 0], F[0, 1]
    S[i, 0], S[i, 1] = F[0, 0] - beta * B[0] * f0, F[0, 1] - beta * B[0] * f1
    S[i, 2], S[i, 3] = F[1, 0] - beta * B[1] * f0, F[1, 1] - beta * B[1] * f1
    S[i, 4], S[i, 5], S[i, 6] = c * B[0] * B[0], c * B[0] * B[1], c * B[1] * B[1]
    S[i, 7], S[i, 8], S[i, 9] = w * f0 * f0, w * f0 * f1, w * f1 * f1
    for m in range(D.shape[1]):
        yy = y[t, m]
        D[i, m, 0], D[i, m, 1] = beta * yy * B[0], beta * yy * B[1]
        D[i, m, 2], D[i, m, 3] = w * yy * f0, w * yy * f1


@jit.kernel(inline=True)
def _append(F: np.ndarray, B: np.ndarray, fr: np.ndarray, y: np.ndarray, t: int, Sg: np.ndarray, Dg: np.ndarray,
            ig: int, S: np.ndarray, D: np.ndarray, i: int) -> None:
    """g then the frame (FrameModel.append: a KF update of the composition by Sherman–Morrison, then its predict)."""
    w, c, beta = fr[t, 0], fr[t, 1], fr[t, 2]
    f0, f1 = F[0, 0], F[0, 1]
    a00, a01, a10, a11 = Sg[ig, 0], Sg[ig, 1], Sg[ig, 2], Sg[ig, 3]
    c00, c01, c11, j00, j01, j11 = Sg[ig, 4], Sg[ig, 5], Sg[ig, 6], Sg[ig, 7], Sg[ig, 8], Sg[ig, 9]
    u0, u1 = c00 * f0 + c01 * f1, c01 * f0 + c11 * f1  # C_g fᵀ
    v0, v1 = f0 * a00 + f1 * a10, f0 * a01 + f1 * a11  # f A_g
    k = w / (1.0 + w * (f0 * u0 + f1 * u1))
    p00, p01, p10, p11 = a00 - k * u0 * v0, a01 - k * u0 * v1, a10 - k * u1 * v0, a11 - k * u1 * v1  # M A_g
    d00, d01, d11 = c00 - k * u0 * u0, c01 - k * u0 * u1, c11 - k * u1 * u1  # M C_g
    e00, e01 = F[0, 0] - beta * B[0] * f0, F[0, 1] - beta * B[0] * f1
    e10, e11 = F[1, 0] - beta * B[1] * f0, F[1, 1] - beta * B[1] * f1
    S[i, 0], S[i, 1] = e00 * p00 + e01 * p10, e00 * p01 + e01 * p11
    S[i, 2], S[i, 3] = e10 * p00 + e11 * p10, e10 * p01 + e11 * p11
    s00, s01, s10, s11 = e00 * d00 + e01 * d01, e00 * d01 + e01 * d11, e10 * d00 + e11 * d01, e10 * d01 + e11 * d11
    S[i, 4] = s00 * e00 + s01 * e01 + c * B[0] * B[0]
    S[i, 5] = s00 * e10 + s01 * e11 + c * B[0] * B[1]
    S[i, 6] = s10 * e10 + s11 * e11 + c * B[1] * B[1]
    S[i, 7], S[i, 8], S[i, 9] = j00 + k * v0 * v0, j01 + k * v0 * v1, j11 + k * v1 * v1
    for m in range(D.shape[1]):
        yy = y[t, m]
        b0, b1, h0, h1 = Dg[ig, m, 0], Dg[ig, m, 1], Dg[ig, m, 2], Dg[ig, m, 3]
        eps = k * (yy - (f0 * b0 + f1 * b1))
        m0, m1 = b0 + eps * u0, b1 + eps * u1  # M (b_g + C_g η_j)
        D[i, m, 0], D[i, m, 1] = e00 * m0 + e01 * m1 + beta * yy * B[0], e10 * m0 + e11 * m1 + beta * yy * B[1]
        D[i, m, 2], D[i, m, 3] = h0 + eps * v0, h1 + eps * v1


@jit.kernel(inline=True)
def _prepend(F: np.ndarray, B: np.ndarray, fr: np.ndarray, y: np.ndarray, t: int, Sg: np.ndarray, Dg: np.ndarray,
             ig: int, S: np.ndarray, D: np.ndarray, i: int) -> None:
    """The frame then g (FrameModel.prepend: Sherman–Morrison with the rank-one C of one frame)."""
    w, c, beta = fr[t, 0], fr[t, 1], fr[t, 2]
    f0, f1 = F[0, 0], F[0, 1]
    a00, a01, a10, a11 = Sg[ig, 0], Sg[ig, 1], Sg[ig, 2], Sg[ig, 3]
    c00, c01, c11, j00, j01, j11 = Sg[ig, 4], Sg[ig, 5], Sg[ig, 6], Sg[ig, 7], Sg[ig, 8], Sg[ig, 9]
    z0, z1 = j00 * B[0] + j01 * B[1], j01 * B[0] + j11 * B[1]  # J_g B
    rho = 1.0 + c * (B[0] * z0 + B[1] * z1)
    k, inv_rho = c / rho, 1.0 / rho
    r0, r1 = a00 * B[0] + a01 * B[1], a10 * B[0] + a11 * B[1]  # A_g B
    t00, t01, t10, t11 = a00 - k * r0 * z0, a01 - k * r0 * z1, a10 - k * r1 * z0, a11 - k * r1 * z1  # A_g M
    i00, i01, i11 = j00 - k * z0 * z0, j01 - k * z0 * z1, j11 - k * z1 * z1  # Mᵀ J_g
    e00, e01 = F[0, 0] - beta * B[0] * f0, F[0, 1] - beta * B[0] * f1
    e10, e11 = F[1, 0] - beta * B[1] * f0, F[1, 1] - beta * B[1] * f1
    S[i, 0], S[i, 1] = t00 * e00 + t01 * e10, t00 * e01 + t01 * e11
    S[i, 2], S[i, 3] = t10 * e00 + t11 * e10, t10 * e01 + t11 * e11
    S[i, 4], S[i, 5], S[i, 6] = k * r0 * r0 + c00, k * r0 * r1 + c01, k * r1 * r1 + c11
    s00, s01, s10, s11 = i00 * e00 + i01 * e10, i00 * e01 + i01 * e11, i01 * e00 + i11 * e10, i01 * e01 + i11 * e11
    S[i, 7] = e00 * s00 + e10 * s10 + w * f0 * f0
    S[i, 8] = e00 * s01 + e10 * s11 + w * f0 * f1
    S[i, 9] = e01 * s01 + e11 * s11 + w * f1 * f1
    for m in range(D.shape[1]):
        yy = y[t, m]
        b0, b1, h0, h1 = Dg[ig, m, 0], Dg[ig, m, 1], Dg[ig, m, 2], Dg[ig, m, 3]
        gamma = (beta * yy + c * (B[0] * h0 + B[1] * h1)) * inv_rho
        n0, n1 = h0 - beta * yy * z0, h1 - beta * yy * z1  # η_g − J_g b_e
        bn = B[0] * n0 + B[1] * n1
        n0, n1 = n0 - k * bn * z0, n1 - k * bn * z1  # Mᵀ (η_g − J_g b_e)
        D[i, m, 0], D[i, m, 1] = gamma * r0 + b0, gamma * r1 + b1
        D[i, m, 2], D[i, m, 3] = e00 * n0 + e10 * n1 + w * yy * f0, e01 * n0 + e11 * n1 + w * yy * f1


@jit.kernel(inline=True)
def _combine(Si: np.ndarray, Di: np.ndarray, ii: int, Sj: np.ndarray, Dj: np.ndarray, ij: int, S: np.ndarray, D: np.ndarray,
             i: int) -> None:
    """i then j (window_scan.combine with covariance=False: the C rows of S are left unset)."""
    a00, a01, a10, a11 = Si[ii, 0], Si[ii, 1], Si[ii, 2], Si[ii, 3]
    c00, c01, c11, j00, j01, j11 = Si[ii, 4], Si[ii, 5], Si[ii, 6], Si[ii, 7], Si[ii, 8], Si[ii, 9]
    A00, A01, A10, A11, J00, J01, J11 = Sj[ij, 0], Sj[ij, 1], Sj[ij, 2], Sj[ij, 3], Sj[ij, 7], Sj[ij, 8], Sj[ij, 9]
    cj00, cj01 = c00 * J00 + c01 * J01, c00 * J01 + c01 * J11  # C_i J_j
    cj10, cj11 = c01 * J00 + c11 * J01, c01 * J01 + c11 * J11
    det = (1.0 + cj00) * (1.0 + cj11) - cj01 * cj10
    inv = 1.0 / det
    m00, m01, m10, m11 = (1.0 + cj11) * inv, -cj01 * inv, -cj10 * inv, (1.0 + cj00) * inv  # M = (I + C_i J_j)⁻¹
    t00, t01 = A00 * m00 + A01 * m10, A00 * m01 + A01 * m11  # T = A_j M
    t10, t11 = A10 * m00 + A11 * m10, A10 * m01 + A11 * m11
    S[i, 0], S[i, 1] = t00 * a00 + t01 * a10, t00 * a01 + t01 * a11
    S[i, 2], S[i, 3] = t10 * a00 + t11 * a10, t10 * a01 + t11 * a11
    n00, n01 = m00 * a00 + m01 * a10, m00 * a01 + m01 * a11  # N = M A_i
    n10, n11 = m10 * a00 + m11 * a10, m10 * a01 + m11 * a11
    r00, r01 = J00 * a00 + J01 * a10, J00 * a01 + J01 * a11  # J_j A_i
    r10, r11 = J01 * a00 + J11 * a10, J01 * a01 + J11 * a11
    S[i, 7] = n00 * r00 + n10 * r10 + j00
    S[i, 8] = n00 * r01 + n10 * r11 + j01
    S[i, 9] = n01 * r01 + n11 * r11 + j11
    for m in range(D.shape[1]):
        b0, b1, h0, h1 = Di[ii, m, 0], Di[ii, m, 1], Di[ii, m, 2], Di[ii, m, 3]
        B0, B1, H0, H1 = Dj[ij, m, 0], Dj[ij, m, 1], Dj[ij, m, 2], Dj[ij, m, 3]
        u0, u1 = b0 + c00 * H0 + c01 * H1, b1 + c01 * H0 + c11 * H1  # b_i + C_i η_j
        D[i, m, 0], D[i, m, 1] = t00 * u0 + t01 * u1 + B0, t10 * u0 + t11 * u1 + B1
        v0, v1 = H0 - (J00 * b0 + J01 * b1), H1 - (J01 * b0 + J11 * b1)  # η_j − J_j b_i
        D[i, m, 2], D[i, m, 3] = n00 * v0 + n10 * v1 + h0, n01 * v0 + n11 * v1 + h1


@jit.kernel(inline=True)
def _estimate(S: np.ndarray, D: np.ndarray, i: int, prior: bool, y: np.ndarray, a: int, P0: np.ndarray, X: np.ndarray,
              channels: np.ndarray, n: int, scale: float) -> None:
    """X[channels[m], n] = scale × x_n of composition (S[i], D[i, m]) for each channel m: flat prior A J⁻¹ η + b
    (J scaled to unit size first), or with the prior N([y[a, m], 0], P0) on the state before the window:
    x̂ = μ + P0 (I + J P0)⁻¹ (η − J μ), then A x̂ + b. The 2×2 inverses are formed once for all channels."""
    j00, j01, j11 = S[i, 7], S[i, 8], S[i, 9]
    if prior:
        p00, p01, p11 = P0[0, 0], P0[0, 1], P0[1, 1]
        i00, i01 = 1.0 + j00 * p00 + j01 * p01, j00 * p01 + j01 * p11  # I + J P0
        i10, i11 = j01 * p00 + j11 * p01, 1.0 + j01 * p01 + j11 * p11
        inv = 1.0 / (i00 * i11 - i01 * i10)
    else:
        unit = 1.0 / max(abs(j00), abs(j11))
        j00, j01, j11 = j00 * unit, j01 * unit, j11 * unit
        inv = unit / (j00 * j11 - j01 * j01)
    for m in range(channels.size):
        h0, h1 = D[i, m, 2], D[i, m, 3]
        if prior:
            mean0 = y[a, m]
            v0, v1 = h0 - j00 * mean0, h1 - j01 * mean0  # η − J μ
            w0, w1 = (i11 * v0 - i01 * v1) * inv, (i00 * v1 - i10 * v0) * inv
            x0, x1 = mean0 + p00 * w0 + p01 * w1, p01 * w0 + p11 * w1
        else:
            x0, x1 = (j11 * h0 - j01 * h1) * inv, (j00 * h1 - j01 * h0) * inv
        X[channels[m], n, 0] = (S[i, 0] * x0 + S[i, 1] * x1 + D[i, m, 0]) * scale
        X[channels[m], n, 1] = (S[i, 2] * x0 + S[i, 3] * x1 + D[i, m, 1]) * scale


@jit.kernel
def window_kf_scan(z: np.ndarray, valid: np.ndarray, members: np.ndarray, L: np.ndarray, q: np.ndarray,
                   sigma_v: np.ndarray, prior: bool, P0: np.ndarray, F: np.ndarray, B: np.ndarray, X: np.ndarray) -> None:
    """X[c, n] (frame units) of the start-up frames n < L − 1 (window [0, n]) and the full windows [n − L + 1, n]
    holding a missing sample, for R groups ``members`` (R, k) of channels of ``z`` (C, T) sharing ``valid`` (C, T),
    window length ``L`` (R,), q = (σ_w/σ_v)² (R,), σ_v (R,) and, with ``prior`` (OFIR), the horizon-start prior
    covariance ``P0`` (R, 2, 2) in units of σ_v². ``F`` (2, 2), ``B`` (2,): the axis model in frame units."""
    T = z.shape[1]
    k = members.shape[1]
    pS, sS, wS = np.empty((T, 10)), np.empty((T, 10)), np.empty((2, 10))  # prefix, suffix, work
    pD, sD, wD = np.empty((T, k, 4)), np.empty((T, k, 4)), np.empty((2, k, 4))
    y = np.empty((T, k))  # samples scaled by σ_v, 0 where missing
    fr = np.empty((T, 3))  # w, c, β of every frame
    count = np.empty(T + 1, np.int64)  # valid samples before frame t
    following = np.empty(T + 1, np.int64)  # first valid frame at or after t (T: none)
    for r in range(members.shape[0]):
        c0, Lr, qr, sv = members[r, 0], L[r], q[r], sigma_v[r]
        S_meas = qr * B[0] * B[0] + 1.0  # S = q B_0² + 1 of a measured frame
        count[0] = 0
        for t in range(T):
            ok = valid[c0, t]
            count[t + 1] = count[t] + (1 if ok else 0)
            fr[t, 0], fr[t, 1], fr[t, 2] = (1.0 / S_meas, qr / S_meas, qr * B[0] / S_meas) if ok else (0.0, qr, 0.0)
            for m in range(k):
                y[t, m] = z[members[r, m], t] / sv if ok else 0.0
        following[T] = T
        for t in range(T - 1, -1, -1):
            following[t] = t if valid[c0, t] else following[t + 1]
        if T >= Lr and count[T] < T:  # some full window holds a missing sample: prefix and suffix compositions of each block
            for t in range(T):
                if t % Lr == 0:
                    _element(F, B, fr, y, t, pS, pD, t)
                else:
                    _append(F, B, fr, y, t, pS, pD, t - 1, pS, pD, t)
            for t in range(T - 1, -1, -1):
                if t % Lr == Lr - 1 or t == T - 1:
                    _element(F, B, fr, y, t, sS, sD, t)
                else:
                    _prepend(F, B, fr, y, t, sS, sD, t + 1, sS, sD, t)
        running = -1  # start-up: the frame the running composition wS[0] has reached
        for n in range(T):
            first = max(0, n - Lr + 1)
            if n >= Lr - 1 and count[n + 1] - count[first] == Lr:  # a clean full window: the caller's kernel
                continue
            if count[n + 1] - count[first] < 2:
                for m in range(k):
                    X[members[r, m], n, 0] = X[members[r, m], n, 1] = np.nan
                continue
            a = following[first]
            lo = a + 1 if prior else first
            start = n - n % Lr
            end = min(start + Lr - 1, T - 1)
            if n < Lr - 1:  # start-up: one running composition from lo (in place: _append reads g first)
                if running < lo:
                    _element(F, B, fr, y, lo, wS, wD, 0)
                    running = lo
                while running < n:
                    running += 1
                    _append(F, B, fr, y, running, wS, wD, 0, wS, wD, 0)
                S, D, i = wS, wD, 0
            elif lo == start:
                S, D, i = pS, pD, n
            elif lo < start:
                _combine(sS, sD, lo, pS, pD, n, wS, wD, 1)
                S, D, i = wS, wD, 1
            elif n == end:
                S, D, i = sS, sD, lo
            else:  # inside one block, touching neither end: frame by frame
                _element(F, B, fr, y, lo, wS, wD, 1)
                for t in range(lo + 1, n + 1):
                    _append(F, B, fr, y, t, wS, wD, 1, wS, wD, 1)
                S, D, i = wS, wD, 1
            _estimate(S, D, i, prior, y, a, P0[r], X, members[r], n, sv)
