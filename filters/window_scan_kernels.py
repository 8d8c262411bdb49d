"""Compiled window scan of the window-KF FIR back ends (OUFIR, OFIR, Kwon's FIR): their start-up windows, the
windows holding a missing sample and, for channels with a missing sample, every other window too — all frames of a
channel group in one pass.

The per-frame elements and the associative composition of :mod:`bboxtune.filters.window_scan` (Särkkä &
García-Fernández, IEEE TAC 2021, Lemmas 7–8), written out per frame: the rank-one single-frame forms
(``FrameModel.append``, ``FrameModel.prepend``) and the general ``combine`` without its covariance rows. Frames are
cut into blocks of the window length L with prefix (block start … t) and suffix (t … block end) compositions, built
in one loop (the two recursions are independent chains, so the CPU overlaps them); a window [lo, n] is one suffix
then one prefix, one prefix (lo at a block start) or one suffix (n at a block end), and a window inside one block
touching neither end is composed frame by frame. Start-up windows (n < L − 1) all start at the track's first
frames: one running composition. The estimate is ``flat_prior_estimate`` (OUFIR, Kwon: lo = the window's first
frame) or ``prior_estimate`` with the prior [y_a, 0], P0 at the window's oldest valid sample a (OFIR: lo = a + 1).
Windows with fewer than 2 valid samples get fir_core's fallback (the latest valid sample, velocity 0).

A composition's structure S = (A00, A01, A10, A11, C00, C01, C11, J00, J01, J11) is shared by the k channels of a
group (same missing frames and parameters: the coordinates of a box), its data D = (b0, b1, η0, η1) is per channel.
The helpers take and return them as tuples of floats — no arrays, so no reference counting in the loops (helpers
with array arguments, inlined, spent half the time on it) — split into a structure step, which also returns the
coefficients its data step needs, and a data step per channel. The numpy references are
:meth:`bboxtune.filters.oufir.KalmanWindowFIR._startup` and :meth:`~bboxtune.filters.oufir.KalmanWindowFIR._masked`
(``$BBOXTUNE_JIT=0``), with the FFT kernel for the clean full windows. :func:`scan_channels` groups the channels and
splits the groups over threads.
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit
from bboxtune.filters.threads import in_threads

Floats = tuple[float, ...]


@jit.kernel
def _element(model: Floats, w: float, c: float, beta: float) -> Floats:
    """Structure of one frame: A = F − β B f, C = c B Bᵀ, J = w fᵀ f (f = H F; ``model`` = F00 F01 F10 F11 B0 B1)."""
    F00, F01, F10, F11, B0, B1 = model
    return (F00 - beta * B0 * F00, F01 - beta * B0 * F01, F10 - beta * B1 * F00, F11 - beta * B1 * F01,
            c * B0 * B0, c * B0 * B1, c * B1 * B1, w * F00 * F00, w * F00 * F01, w * F01 * F01)


@jit.kernel
def _element_data(model: Floats, w: float, beta: float, y: float) -> Floats:
    """Data of one frame with sample y: b = β y B, η = w y fᵀ."""
    F00, F01, F10, F11, B0, B1 = model
    return beta * y * B0, beta * y * B1, w * y * F00, w * y * F01


@jit.kernel
def _append(model: Floats, g: Floats, w: float, c: float, beta: float) -> tuple[Floats, Floats]:
    """Structure of g then the frame (FrameModel.append: a KF update of the composition by Sherman–Morrison, then
    its predict), and the coefficients of :func:`_append_data`."""
    F00, F01, F10, F11, B0, B1 = model
    f0, f1 = F00, F01
    a00, a01, a10, a11, c00, c01, c11, j00, j01, j11 = g
    u0, u1 = c00 * f0 + c01 * f1, c01 * f0 + c11 * f1  # C_g fᵀ
    v0, v1 = f0 * a00 + f1 * a10, f0 * a01 + f1 * a11  # f A_g
    k = w / (1.0 + w * (f0 * u0 + f1 * u1))
    p00, p01, p10, p11 = a00 - k * u0 * v0, a01 - k * u0 * v1, a10 - k * u1 * v0, a11 - k * u1 * v1  # M A_g
    d00, d01, d11 = c00 - k * u0 * u0, c01 - k * u0 * u1, c11 - k * u1 * u1  # M C_g
    e00, e01 = F00 - beta * B0 * f0, F01 - beta * B0 * f1
    e10, e11 = F10 - beta * B1 * f0, F11 - beta * B1 * f1
    s00, s01, s10, s11 = e00 * d00 + e01 * d01, e00 * d01 + e01 * d11, e10 * d00 + e11 * d01, e10 * d01 + e11 * d11
    S = (e00 * p00 + e01 * p10, e00 * p01 + e01 * p11, e10 * p00 + e11 * p10, e10 * p01 + e11 * p11,
         s00 * e00 + s01 * e01 + c * B0 * B0, s00 * e10 + s01 * e11 + c * B0 * B1, s10 * e10 + s11 * e11 + c * B1 * B1,
         j00 + k * v0 * v0, j01 + k * v0 * v1, j11 + k * v1 * v1)
    return S, (k, u0, u1, v0, v1, e00, e01, e10, e11)


@jit.kernel
def _append_data(model: Floats, coef: Floats, g: Floats, beta: float, y: float) -> Floats:
    """Data of g (``g`` = b0 b1 η0 η1) then the frame with sample y, from :func:`_append`'s coefficients."""
    F00, F01, F10, F11, B0, B1 = model
    k, u0, u1, v0, v1, e00, e01, e10, e11 = coef
    b0, b1, h0, h1 = g
    eps = k * (y - (F00 * b0 + F01 * b1))
    m0, m1 = b0 + eps * u0, b1 + eps * u1  # M (b_g + C_g η_j)
    return e00 * m0 + e01 * m1 + beta * y * B0, e10 * m0 + e11 * m1 + beta * y * B1, h0 + eps * v0, h1 + eps * v1


@jit.kernel
def _prepend(model: Floats, g: Floats, w: float, c: float, beta: float) -> tuple[Floats, Floats]:
    """Structure of the frame then g (FrameModel.prepend: Sherman–Morrison with the rank-one C of one frame), and
    the coefficients of :func:`_prepend_data`."""
    F00, F01, F10, F11, B0, B1 = model
    f0, f1 = F00, F01
    a00, a01, a10, a11, c00, c01, c11, j00, j01, j11 = g
    z0, z1 = j00 * B0 + j01 * B1, j01 * B0 + j11 * B1  # J_g B
    rho = 1.0 + c * (B0 * z0 + B1 * z1)
    k, inv_rho = c / rho, 1.0 / rho
    r0, r1 = a00 * B0 + a01 * B1, a10 * B0 + a11 * B1  # A_g B
    t00, t01, t10, t11 = a00 - k * r0 * z0, a01 - k * r0 * z1, a10 - k * r1 * z0, a11 - k * r1 * z1  # A_g M
    i00, i01, i11 = j00 - k * z0 * z0, j01 - k * z0 * z1, j11 - k * z1 * z1  # Mᵀ J_g
    e00, e01 = F00 - beta * B0 * f0, F01 - beta * B0 * f1
    e10, e11 = F10 - beta * B1 * f0, F11 - beta * B1 * f1
    s00, s01, s10, s11 = i00 * e00 + i01 * e10, i00 * e01 + i01 * e11, i01 * e00 + i11 * e10, i01 * e01 + i11 * e11
    S = (t00 * e00 + t01 * e10, t00 * e01 + t01 * e11, t10 * e00 + t11 * e10, t10 * e01 + t11 * e11,
         k * r0 * r0 + c00, k * r0 * r1 + c01, k * r1 * r1 + c11,
         e00 * s00 + e10 * s10 + w * f0 * f0, e00 * s01 + e10 * s11 + w * f0 * f1, e01 * s01 + e11 * s11 + w * f1 * f1)
    return S, (k, inv_rho, z0, z1, r0, r1, e00, e01, e10, e11)


@jit.kernel
def _prepend_data(model: Floats, coef: Floats, g: Floats, w: float, c: float, beta: float, y: float) -> Floats:
    """Data of the frame with sample y then g, from :func:`_prepend`'s coefficients."""
    F00, F01, F10, F11, B0, B1 = model
    k, inv_rho, z0, z1, r0, r1, e00, e01, e10, e11 = coef
    b0, b1, h0, h1 = g
    gamma = (beta * y + c * (B0 * h0 + B1 * h1)) * inv_rho
    n0, n1 = h0 - beta * y * z0, h1 - beta * y * z1  # η_g − J_g b_e
    bn = B0 * n0 + B1 * n1
    n0, n1 = n0 - k * bn * z0, n1 - k * bn * z1  # Mᵀ (η_g − J_g b_e)
    return gamma * r0 + b0, gamma * r1 + b1, e00 * n0 + e10 * n1 + w * y * F00, e01 * n0 + e11 * n1 + w * y * F01


@jit.kernel
def _combine(Si: Floats, Sj: Floats) -> tuple[Floats, Floats]:
    """Structure of i then j (window_scan.combine with covariance=False: C is NaN), and the coefficients of
    :func:`_combine_data`."""
    a00, a01, a10, a11, c00, c01, c11, j00, j01, j11 = Si
    A00, A01, A10, A11, _, _, _, J00, J01, J11 = Sj
    cj00, cj01 = c00 * J00 + c01 * J01, c00 * J01 + c01 * J11  # C_i J_j
    cj10, cj11 = c01 * J00 + c11 * J01, c01 * J01 + c11 * J11
    inv = 1.0 / ((1.0 + cj00) * (1.0 + cj11) - cj01 * cj10)
    m00, m01, m10, m11 = (1.0 + cj11) * inv, -cj01 * inv, -cj10 * inv, (1.0 + cj00) * inv  # M = (I + C_i J_j)⁻¹
    t00, t01 = A00 * m00 + A01 * m10, A00 * m01 + A01 * m11  # T = A_j M
    t10, t11 = A10 * m00 + A11 * m10, A10 * m01 + A11 * m11
    n00, n01 = m00 * a00 + m01 * a10, m00 * a01 + m01 * a11  # N = M A_i
    n10, n11 = m10 * a00 + m11 * a10, m10 * a01 + m11 * a11
    r00, r01 = J00 * a00 + J01 * a10, J00 * a01 + J01 * a11  # J_j A_i
    r10, r11 = J01 * a00 + J11 * a10, J01 * a01 + J11 * a11
    S = (t00 * a00 + t01 * a10, t00 * a01 + t01 * a11, t10 * a00 + t11 * a10, t10 * a01 + t11 * a11,
         np.nan, np.nan, np.nan,
         n00 * r00 + n10 * r10 + j00, n00 * r01 + n10 * r11 + j01, n01 * r01 + n11 * r11 + j11)
    return S, (t00, t01, t10, t11, n00, n01, n10, n11, c00, c01, c11, J00, J01, J11)


@jit.kernel
def _combine_data(coef: Floats, Di: Floats, Dj: Floats) -> Floats:
    """Data of i then j, from :func:`_combine`'s coefficients."""
    t00, t01, t10, t11, n00, n01, n10, n11, c00, c01, c11, J00, J01, J11 = coef
    b0, b1, h0, h1 = Di
    B0, B1, H0, H1 = Dj
    u0, u1 = b0 + c00 * H0 + c01 * H1, b1 + c01 * H0 + c11 * H1  # b_i + C_i η_j
    v0, v1 = H0 - (J00 * b0 + J01 * b1), H1 - (J01 * b0 + J11 * b1)  # η_j − J_j b_i
    return t00 * u0 + t01 * u1 + B0, t10 * u0 + t11 * u1 + B1, n00 * v0 + n10 * v1 + h0, n01 * v0 + n11 * v1 + h1


@jit.kernel
def _estimate(S: Floats, prior: bool, P0: Floats) -> Floats:
    """The 2×2 inverse of a window's estimate, formed once for its channels: with the prior N(μ, ``P0`` = p00 p01 p11)
    on the state before the window (I + J P0 and 1 / its determinant), or flat (J scaled to unit size first)."""
    j00, j01, j11 = S[7], S[8], S[9]
    if prior:
        p00, p01, p11 = P0
        i00, i01 = 1.0 + j00 * p00 + j01 * p01, j00 * p01 + j01 * p11  # I + J P0
        i10, i11 = j01 * p00 + j11 * p01, 1.0 + j01 * p01 + j11 * p11
        return j00, j01, j11, i00, i01, i10, i11, 1.0 / (i00 * i11 - i01 * i10)
    unit = 1.0 / max(abs(j00), abs(j11))
    j00, j01, j11 = j00 * unit, j01 * unit, j11 * unit
    return j00, j01, j11, 0.0, 0.0, 0.0, 0.0, unit / (j00 * j11 - j01 * j01)


@jit.kernel
def _estimate_data(S: Floats, coef: Floats, prior: bool, P0: Floats, D: Floats, mean: float) -> tuple[float, float]:
    """x_n of one channel with data D: A (μ + P0 (I + J P0)⁻¹ (η − J μ)) + b with μ = [``mean``, 0], or flat
    A J⁻¹ η + b."""
    j00, j01, j11, i00, i01, i10, i11, inv = coef
    h0, h1 = D[2], D[3]
    if prior:
        p00, p01, p11 = P0
        v0, v1 = h0 - j00 * mean, h1 - j01 * mean  # η − J μ
        w0, w1 = (i11 * v0 - i01 * v1) * inv, (i00 * v1 - i10 * v0) * inv
        x0, x1 = mean + p00 * w0 + p01 * w1, p01 * w0 + p11 * w1
    else:
        x0, x1 = (j11 * h0 - j01 * h1) * inv, (j00 * h1 - j01 * h0) * inv
    return S[0] * x0 + S[1] * x1 + D[0], S[2] * x0 + S[3] * x1 + D[1]


@jit.kernel
def window_kf_scan(z: np.ndarray, valid: np.ndarray, members: np.ndarray, L: np.ndarray, q: np.ndarray,
                   sigma_v: np.ndarray, prior: bool, P0: np.ndarray, F: np.ndarray, B: np.ndarray, every: np.ndarray,
                   X: np.ndarray) -> int:
    """X[c, n] (frame units) of the start-up frames n < L − 1 (window [0, n]), the full windows [n − L + 1, n]
    holding a missing sample and, where ``every`` (R,) is True, all other frames too, for R groups ``members``
    (R, k) of channels of ``z`` (C, T) sharing ``valid`` (C, T), window length ``L`` (R,), q = (σ_w/σ_v)² (R,),
    σ_v (R,) and, with ``prior`` (OFIR), the horizon-start prior covariance ``P0`` (R, 2, 2) in units of σ_v².
    ``F`` (2, 2), ``B`` (2,): the axis model in frame units. Windows with fewer than 2 valid samples get fir_core's
    fallback (the latest valid sample, velocity 0; NaN before the first). Returns how many windows of at least 2
    valid samples came out with a NaN position (a numerical failure, for the caller to report)."""
    T = z.shape[1]
    k = members.shape[1]
    model = (F[0, 0], F[0, 1], F[1, 0], F[1, 1], B[0], B[1])
    pS, sS = np.empty((T, 10)), np.empty((T, 10))  # prefix, suffix compositions: structure, data
    pD, sD, wD = np.empty((T, k, 4)), np.empty((T, k, 4)), np.empty((k, 4))  # wD: the running start-up data
    y = np.empty((T, k))  # samples scaled by σ_v, 0 where missing
    fr = np.empty((T, 3))  # w, c, β of every frame
    count = np.empty(T + 1, np.int64)  # valid samples before frame t
    following = np.empty(T + 1, np.int64)  # first valid frame at or after t (T: none)
    gp = gs = gw = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # compositions: prefix, suffix, running
    cc = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # coefficients of a combine
    failures = 0
    for r in range(members.shape[0]):
        c0, Lr, qr, sv, all_frames = members[r, 0], L[r], q[r], sigma_v[r], every[r]
        P0r = (P0[r, 0, 0], P0[r, 0, 1], P0[r, 1, 1])
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
        if T >= Lr and (all_frames or count[T] < T):  # full windows to compose: prefix and suffix of each block
            i_offset, t_offset = 0, (T - 1) % Lr  # offsets in their blocks (no integer division per frame)
            for i in range(T):  # prefix at frame i, suffix at frame t = T − 1 − i
                t = T - 1 - i
                w, c, beta = fr[i, 0], fr[i, 1], fr[i, 2]
                if i_offset == 0:
                    gp = _element(model, w, c, beta)
                    for m in range(k):
                        pD[i, m, 0], pD[i, m, 1], pD[i, m, 2], pD[i, m, 3] = _element_data(model, w, beta, y[i, m])
                else:
                    gp, coef = _append(model, gp, w, c, beta)
                    for m in range(k):
                        pD[i, m, 0], pD[i, m, 1], pD[i, m, 2], pD[i, m, 3] = _append_data(
                            model, coef, (pD[i - 1, m, 0], pD[i - 1, m, 1], pD[i - 1, m, 2], pD[i - 1, m, 3]), beta,
                            y[i, m])
                w, c, beta = fr[t, 0], fr[t, 1], fr[t, 2]
                if t_offset == Lr - 1 or t == T - 1:
                    gs = _element(model, w, c, beta)
                    for m in range(k):
                        sD[t, m, 0], sD[t, m, 1], sD[t, m, 2], sD[t, m, 3] = _element_data(model, w, beta, y[t, m])
                else:
                    gs, coef = _prepend(model, gs, w, c, beta)
                    for m in range(k):
                        sD[t, m, 0], sD[t, m, 1], sD[t, m, 2], sD[t, m, 3] = _prepend_data(
                            model, coef, (sD[t + 1, m, 0], sD[t + 1, m, 1], sD[t + 1, m, 2], sD[t + 1, m, 3]), w, c,
                            beta, y[t, m])
                for j in range(10):
                    pS[i, j] = gp[j]
                    sS[t, j] = gs[j]
                i_offset = 0 if i_offset == Lr - 1 else i_offset + 1
                t_offset = Lr - 1 if t_offset == 0 else t_offset - 1
        running = -1  # start-up: the frame the running composition (gw, wD) has reached
        latest = -1  # the latest valid frame at or before n
        start = 0  # the first frame of n's block
        for n in range(T):
            if n > 0 and n - start == Lr:
                start = n
            if valid[c0, n]:
                latest = n
            first = max(0, n - Lr + 1)
            if n >= Lr - 1 and count[n + 1] - count[first] == Lr and not all_frames:  # clean: the FFT kernel's
                continue
            if count[n + 1] - count[first] < 2:  # unobservable: the latest valid sample, velocity 0 (NaN: none yet)
                for m in range(k):
                    X[members[r, m], n, 0] = z[members[r, m], latest] if latest >= 0 else np.nan
                    X[members[r, m], n, 1] = 0.0 if latest >= 0 else np.nan
                continue
            a = following[first]
            lo = a + 1 if prior else first
            end = min(start + Lr - 1, T - 1)
            if n < Lr - 1 or (lo > start and n < end):  # start-up, or inside one block: frame by frame from lo
                if n >= Lr - 1 or running < lo:  # (start-up windows all start at lo: one running composition)
                    gw = _element(model, fr[lo, 0], fr[lo, 1], fr[lo, 2])
                    for m in range(k):
                        wD[m, 0], wD[m, 1], wD[m, 2], wD[m, 3] = _element_data(model, fr[lo, 0], fr[lo, 2], y[lo, m])
                    running = lo
                while running < n:
                    running += 1
                    w, c, beta = fr[running, 0], fr[running, 1], fr[running, 2]
                    gw, coef = _append(model, gw, w, c, beta)
                    for m in range(k):
                        wD[m, 0], wD[m, 1], wD[m, 2], wD[m, 3] = _append_data(
                            model, coef, (wD[m, 0], wD[m, 1], wD[m, 2], wD[m, 3]), beta, y[running, m])
                gn = gw
            elif lo == start:
                gn = (pS[n, 0], pS[n, 1], pS[n, 2], pS[n, 3], pS[n, 4], pS[n, 5], pS[n, 6], pS[n, 7], pS[n, 8], pS[n, 9])
            elif lo < start:
                gn, cc = _combine((sS[lo, 0], sS[lo, 1], sS[lo, 2], sS[lo, 3], sS[lo, 4], sS[lo, 5], sS[lo, 6],
                                   sS[lo, 7], sS[lo, 8], sS[lo, 9]),
                                  (pS[n, 0], pS[n, 1], pS[n, 2], pS[n, 3], pS[n, 4], pS[n, 5], pS[n, 6], pS[n, 7],
                                   pS[n, 8], pS[n, 9]))
            else:  # n == end
                gn = (sS[lo, 0], sS[lo, 1], sS[lo, 2], sS[lo, 3], sS[lo, 4], sS[lo, 5], sS[lo, 6], sS[lo, 7],
                      sS[lo, 8], sS[lo, 9])
            ce = _estimate(gn, prior, P0r)
            for m in range(k):
                if n < Lr - 1 or (lo > start and n < end):
                    d = (wD[m, 0], wD[m, 1], wD[m, 2], wD[m, 3])
                elif lo == start:
                    d = (pD[n, m, 0], pD[n, m, 1], pD[n, m, 2], pD[n, m, 3])
                elif lo < start:
                    d = _combine_data(cc, (sD[lo, m, 0], sD[lo, m, 1], sD[lo, m, 2], sD[lo, m, 3]),
                                      (pD[n, m, 0], pD[n, m, 1], pD[n, m, 2], pD[n, m, 3]))
                else:
                    d = (sD[lo, m, 0], sD[lo, m, 1], sD[lo, m, 2], sD[lo, m, 3])
                x0, x1 = _estimate_data(gn, ce, prior, P0r, d, y[a, m])
                X[members[r, m], n, 0], X[members[r, m], n, 1] = x0 * sv, x1 * sv
                if np.isnan(x0):
                    failures += 1
    return failures


def scan_channels(X: np.ndarray, z: np.ndarray, valid: np.ndarray, every: np.ndarray, group: np.ndarray, L: np.ndarray,
                  q: np.ndarray, sigma_v: np.ndarray, prior: bool, P0: np.ndarray, F: np.ndarray, B: np.ndarray) -> int:
    """:func:`window_kf_scan` on the channels of ``z`` (C, T): every frame of those marked ``every`` (C,), the start-up
    frames of the others; per channel the gain parameter group, L, q, σ_v (C,) and P0 (C, 2, 2). 4 consecutive
    channels (a box) with the same missing frames and group share one scan. Large calls run in threads, each on
    its own groups (:func:`bboxtune.filters.threads.in_threads`). Returns the kernel's count of failed estimates."""
    C, T = z.shape
    k = 1
    if C % 4 == 0:
        quad = np.arange(C).reshape(-1, 4)
        k = 4 if (group[quad] == group[quad[:, :1]]).all() and (valid[quad] == valid[quad[:, :1]]).all() else 1
    members = np.arange(C).reshape(-1, k)
    lead = members[:, 0]
    L, q, sv, every = L[lead].astype(np.int64), q[lead].astype(float), sigma_v[lead].astype(float), every[lead]
    P0 = np.ascontiguousarray(P0[lead], dtype=float)
    z, F, B = np.ascontiguousarray(z, dtype=float), np.ascontiguousarray(F, dtype=float), np.ascontiguousarray(B, dtype=float)

    def scan(part: slice) -> int:  # the groups `part`, in a thread of its own (the kernel releases the GIL)
        return window_kf_scan(z, valid, members[part], L[part], q[part], sv[part], prior, P0[part], F, B, every[part], X)

    frames = np.where(every, T, np.minimum(L, T))  # frames the scan visits per group
    return sum(in_threads(scan, members.shape[0], int(frames.mean()) if frames.size else 0))
