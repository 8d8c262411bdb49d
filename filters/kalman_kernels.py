"""Compiled kernels of the Kalman family (:mod:`bboxtune.filters.kalman_core`, :mod:`bboxtune.filters.kf_cmn`): the frame
kinds, KF-CMN's differencing, the step tables of KF and KF-CMN, the gain recursion and the affine application.

Each computes what its numpy reference computes (``kalman_core.frame_kinds_numpy``, ``kf_cmn.differenced_kinds``,
``kalman_core.gain_recursion``, ``kalman_core.apply_affine``): the same equations, in the same order of floating-point
operations, so that the gains come out bit for bit equal to the frame-by-frame numpy path (property tests:
tests/filters/test_kalman_kernels.py).

* :func:`gain_recursion` runs each row on its own, frame by frame, and stops a row once its posterior covariance
  repeats bit for bit after its last change of frame kind (every later frame then repeats it: the map of a frame depends
  only on its kind and the previous covariance). The frame the reference would stop at — the first multiple-of-8 frame
  (n % 8 == 7) by which every row repeats and no kind changes — is derived from the rows' stops, so the outputs match.
* :func:`apply_affine` runs x_n = M_n x_{n−1} + g_n m_n channel by channel (the reference's frame-by-frame form).
* :func:`kf_tables` and :func:`cmn_tables` build the step tables bit for bit as ``kalman_core.plain_tables`` and
  ``kf_cmn.cmn_tables_numpy`` do (tested for 1 … 65 rows): a one-row table cost ~0.2 ms of numpy calls, which a
  one-track call (a reseeded episode's rule run, a step) paid every time.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from bboxtune.filters import jit


class StepTables(Protocol):
    """The per-kind step tables of :class:`bboxtune.filters.kalman_core.StepTables` (kind first, row last): A, Q
    (kinds, 2, 2, G), Lam, D, M (kinds, 2, G), R (kinds, G)."""

    @property
    def A(self) -> np.ndarray: ...
    @property
    def Q(self) -> np.ndarray: ...
    @property
    def Lam(self) -> np.ndarray: ...
    @property
    def D(self) -> np.ndarray: ...
    @property
    def R(self) -> np.ndarray: ...
    @property
    def M(self) -> np.ndarray: ...

WAIT, INIT, PREDICT, UPDATE_Y, UPDATE_Z = range(5)  # kalman_core's frame kinds


def gain_recursion(kinds: np.ndarray, tables: StepTables, P_start: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
    """:func:`bboxtune.filters.kalman_core.gain_recursion` compiled: affine coefficients (T, 6, G) of the rows' frame
    ``kinds`` (G, T) with the step ``tables`` from ``P_start`` (2, 2, G), the steady frame (T if none), the posterior
    covariance (2, 2, G) at the last frame."""
    f64 = [np.ascontiguousarray(a, dtype=np.float64) for a in (tables.A, tables.Q, tables.Lam, tables.D, tables.R,
                                                                tables.M, P_start)]
    kinds = np.ascontiguousarray(kinds, dtype=np.int8 if kinds.dtype == np.int8 else np.int32)
    by_row, steady, P_end = _gain_rows(kinds, *f64)
    return by_row.transpose(1, 2, 0), int(steady), P_end  # (T, 6, G): a view of the rows' coefficients (G, T, 6)


def apply_affine(coef: np.ndarray, steady_from: int, row_of_channel: np.ndarray, m: np.ndarray,
                 x_start: np.ndarray) -> np.ndarray:
    """:func:`bboxtune.filters.kalman_core.apply_affine` compiled: states (C, T, 2) of x_n = M_n x_{n−1} + g_n m_n,
    ``coef`` (T, 6, G) constant from frame ``steady_from`` on, ``row_of_channel`` (C,), ``m`` (C, T), ``x_start`` (C, 2).
    The coefficients are read row first (G, T, 6): :func:`gain_recursion` returns them so, others are transposed."""
    by_row = coef.transpose(2, 0, 1)
    if not (by_row.flags.c_contiguous and by_row.dtype == np.float64):
        by_row = _rows_first(np.ascontiguousarray(coef, dtype=np.float64))
    return _affine_channels(by_row, int(steady_from),
                            np.ascontiguousarray(row_of_channel, dtype=np.int64),
                            np.ascontiguousarray(m, dtype=np.float64), np.ascontiguousarray(x_start, dtype=np.float64))


@jit.kernel
def _joseph_step(a00: float, a01: float, a10: float, a11: float, q00: float, q01: float, q10: float, q11: float,
                 l0: float, l1: float, d0: float, d1: float, r: float, c0: float, c1: float, correlated: bool,
                 p00: float, p01: float, p10: float, p11: float) -> tuple:
    """``kalman_core.joseph_step`` on scalars (the same expressions): the posterior (n00, n01, n10, n11) and the
    affine coefficients [(I − K D) A row-major, g0, g1]; ``correlated``: the time-correlated update with M = (c0, c1)."""
    # P⁻ = A P Aᵀ + Q ([Shmaliy-CMN] Alg. 1 line 5)
    m00 = (a00 * p00 * a00 + a00 * p01 * a01) + (a01 * p10 * a00 + a01 * p11 * a01) + q00
    m01 = (a00 * p00 * a10 + a00 * p01 * a11) + (a01 * p10 * a10 + a01 * p11 * a11) + q01
    m10 = (a10 * p00 * a00 + a10 * p01 * a01) + (a11 * p10 * a00 + a11 * p11 * a01) + q10
    m11 = (a10 * p00 * a10 + a10 * p01 * a11) + (a11 * p10 * a10 + a11 * p11 * a11) + q11
    pd0, pd1 = m00 * d0 + m01 * d1, m10 * d0 + m11 * d1
    if correlated:
        S = d0 * pd0 + d1 * pd1 + 2.0 * (d0 * c0 + d1 * c1) + r  # S = D P⁻ Dᵀ + D M + Mᵀ Dᵀ + R (G6)
        k0, k1 = (pd0 + c0) / S, (pd1 + c1) / S  # K = (P⁻ Dᵀ + M) S⁻¹ (G6)
    else:
        S = d0 * pd0 + d1 * pd1 + r  # S = D P⁻ Dᵀ + R (line 6)
        k0, k1 = pd0 / S, pd1 / S  # K = P⁻ Dᵀ S⁻¹ (line 7)
    i00, i01, i10, i11 = 1.0 - k0 * d0, 0.0 - k0 * d1, 0.0 - k1 * d0, 1.0 - k1 * d1  # I − K D
    # Joseph form (I − KD) P⁻ (I − KD)ᵀ + K R Kᵀ (line 10)
    n00 = (i00 * m00 * i00 + i00 * m01 * i01) + (i01 * m10 * i00 + i01 * m11 * i01) + r * k0 * k0
    n01 = (i00 * m00 * i10 + i00 * m01 * i11) + (i01 * m10 * i10 + i01 * m11 * i11) + r * k0 * k1
    n10 = (i10 * m00 * i00 + i10 * m01 * i01) + (i11 * m10 * i00 + i11 * m11 * i01) + r * k1 * k0
    n11 = (i10 * m00 * i10 + i10 * m01 * i11) + (i11 * m10 * i10 + i11 * m11 * i11) + r * k1 * k1
    if correlated:  # − (I − KD) M Kᵀ − K Mᵀ (I − KD)ᵀ (G7)
        u0, u1 = i00 * c0 + i01 * c1, i10 * c0 + i11 * c1
        n00, n01 = n00 - 2.0 * u0 * k0, n01 - (u0 * k1 + k0 * u1)
        n10, n11 = n10 - (u1 * k0 + k1 * u0), n11 - 2.0 * u1 * k1
    row = (i00 * a00 + i01 * a10, i00 * a01 + i01 * a11, i10 * a00 + i11 * a10, i10 * a01 + i11 * a11,
           i00 * l0 + i01 * l1 + k0, i10 * l0 + i11 * l1 + k1)
    return (n00, n01, n10, n11), row


@jit.kernel
def settled_from(kinds: np.ndarray, g: int) -> int:
    """The first frame from which row ``g``'s frame kinds (G, T) stay constant to the end."""
    T = kinds.shape[1]
    last = T - 1
    while last > 0 and kinds[g, last - 1] == kinds[g, T - 1]:
        last -= 1
    return last


@jit.kernel
def repeat_later(coef: np.ndarray, g: int, n: int) -> None:
    """Row ``g``'s coefficients (G, T, 6) of every frame after ``n`` set to frame ``n``'s (its covariance repeats)."""
    for later in range(n + 1, coef.shape[1]):
        for j in range(6):  # element loops, not slices: a third of the compile time
            coef[g, later, j] = coef[g, n, j]


@jit.kernel
def stop_frame(settled: int, repeat_from: int, T: int) -> int:
    """The frame from which every row's coefficients repeat (T: none repeat), rounded up as the reference checks
    frames n % 8 == 7."""
    stop = max(settled, repeat_from)
    stop += (7 - stop % 8) % 8
    return min(stop, T) if repeat_from < T else T


@jit.kernel
def _gain_rows(kinds: np.ndarray, A: np.ndarray, Q: np.ndarray, Lam: np.ndarray, D: np.ndarray, R: np.ndarray,
               M: np.ndarray, P_start: np.ndarray) -> tuple:
    """The rows' recursions one after the other (see the module docstring); ``kinds`` (G, T) int."""
    G, T = kinds.shape
    n_kinds = R.shape[0]
    correlated = np.zeros(n_kinds, np.bool_)  # kinds with a noise cross-covariance in some row (KF-CMN's gaps)
    for k in range(n_kinds):
        for g in range(G):
            if M[k, 0, g] != 0.0 or M[k, 1, g] != 0.0:
                correlated[k] = True
    coef = np.empty((G, T, 6))  # row first: each row's frames contiguous
    P_end = np.empty((2, 2, G))
    settled, repeat_from = 0, 0  # the last kind change, the last frame a row's covariance starts repeating
    for g in range(G):
        last = settled_from(kinds, g)
        settled = max(settled, last)
        s00, s01, s10, s11 = P_start[0, 0, g], P_start[0, 1, g], P_start[1, 0, g], P_start[1, 1, g]
        p00, p01, p10, p11 = s00, s01, s10, s11
        repeats = T
        for n in range(T):
            k = kinds[g, n]
            if k <= INIT:  # WAIT / INIT: x = [m, 0] (INIT) or 0 (WAIT), covariance back to the start one
                n00, n01, n10, n11 = s00, s01, s10, s11
                for j in range(4):
                    coef[g, n, j] = 0.0
                coef[g, n, 4], coef[g, n, 5] = 1.0 if k == INIT else 0.0, 0.0
            else:
                (n00, n01, n10, n11), row = _joseph_step(
                    A[k, 0, 0, g], A[k, 0, 1, g], A[k, 1, 0, g], A[k, 1, 1, g], Q[k, 0, 0, g], Q[k, 0, 1, g],
                    Q[k, 1, 0, g], Q[k, 1, 1, g], Lam[k, 0, g], Lam[k, 1, g], D[k, 0, g], D[k, 1, g], R[k, g],
                    M[k, 0, g], M[k, 1, g], correlated[k], p00, p01, p10, p11)
                coef[g, n, 0], coef[g, n, 1], coef[g, n, 2], coef[g, n, 3], coef[g, n, 4], coef[g, n, 5] = row
            steady = n00 == p00 and n01 == p01 and n10 == p10 and n11 == p11
            p00, p01, p10, p11 = n00, n01, n10, n11
            if n >= last and steady:  # P_n = P_{n−1} and no kind change later: every later frame repeats frame n
                repeats = n
                repeat_later(coef, g, n)
                break
        repeat_from = max(repeat_from, repeats)
        P_end[0, 0, g], P_end[0, 1, g], P_end[1, 0, g], P_end[1, 1, g] = p00, p01, p10, p11
    return coef, stop_frame(settled, repeat_from, T), P_end


@jit.kernel
def _rows_first(coef: np.ndarray) -> np.ndarray:
    """(T, 6, G) → (G, T, 6), C-contiguous."""
    T, _, G = coef.shape
    by_row = np.empty((G, T, 6))
    for n in range(T):
        for j in range(6):
            for g in range(G):
                by_row[g, n, j] = coef[n, j, g]
    return by_row


@jit.kernel
def _affine_channels(by_row: np.ndarray, steady_from: int, row_of_channel: np.ndarray, m: np.ndarray,
                     x_start: np.ndarray) -> np.ndarray:
    """x_n = M_n x_{n−1} + g_n m_n channel by channel, with the coefficients ``by_row`` (G, T, 6) of frame
    min(n, ``steady_from``)."""
    C, T = m.shape
    last = min(steady_from, T - 1)
    out = np.empty((C, T, 2))
    for c in range(C):
        rc = by_row[row_of_channel[c]]
        p, v = x_start[c, 0], x_start[c, 1]
        for n in range(T):
            f = rc[min(n, last)]
            p, v = f[0] * p + f[1] * v + f[4] * m[c, n], f[2] * p + f[3] * v + f[5] * m[c, n]
            out[c, n, 0], out[c, n, 1] = p, v
    return out



@jit.kernel
def kf_tables(p: np.ndarray, F: np.ndarray, BB: np.ndarray, H: np.ndarray, n_kinds: int) -> tuple:
    """The step tables (A, Q, Lam, D, R, M) of a plain KF (``kalman_core.plain_tables``) for G rows ``p`` = [σ_w, σ_v]
    (G, 2) and ``n_kinds`` kinds, from the axis model's F (2, 2), B Bᵀ (2, 2) and H (2,): Q = σ_w² B Bᵀ, R = σ_v²."""
    G = p.shape[0]
    A, Q, Lam, D, R, M = _empty_tables(n_kinds, G)
    for g in range(G):
        _plain_row(A, Q, D, R, g, p[g, 0] * p[g, 0], p[g, 1] * p[g, 1], F, BB, H)
    return A, Q, Lam, D, R, M


@jit.kernel
def _empty_tables(n_kinds: int, G: int) -> tuple:
    """A, Q (n_kinds, 2, 2, G) to be filled; Lam, D, M (n_kinds, 2, G) 0; R (n_kinds, G) 1."""
    return (np.empty((n_kinds, 2, 2, G)), np.empty((n_kinds, 2, 2, G)), np.zeros((n_kinds, 2, G)),
            np.zeros((n_kinds, 2, G)), np.ones((n_kinds, G)), np.zeros((n_kinds, 2, G)))


@jit.kernel
def _plain_row(A: np.ndarray, Q: np.ndarray, D: np.ndarray, R: np.ndarray, g: int, var_w: float, var_y: float,
               F: np.ndarray, BB: np.ndarray, H: np.ndarray) -> None:
    """Row g of the plain KF's tables: every kind predicts with (F, Q = σ_w² B Bᵀ); UPDATE_Y updates with (H, var_y)."""
    for k in range(A.shape[0]):
        for i in range(2):
            for j in range(2):
                A[k, i, j, g], Q[k, i, j, g] = F[i, j], BB[i, j] * var_w
    D[UPDATE_Y, 0, g], D[UPDATE_Y, 1, g] = H[0], H[1]
    R[UPDATE_Y, g] = var_y


@jit.kernel
def cmn_tables(p: np.ndarray, F: np.ndarray, BB: np.ndarray, H: np.ndarray, H_F_inv: np.ndarray,
               n_kinds: int) -> tuple:
    """The step tables (A, Q, Lam, D, R, M) of :func:`bboxtune.filters.kf_cmn.cmn_tables_numpy` for G rows ``p`` =
    [σ_w, σ_v, ψ] (G, 3) and ``n_kinds`` kinds, from the axis model's F (2, 2), B Bᵀ (2, 2), H (2,) and H F⁻¹ (2,):
    the plain KF's tables for every kind, UPDATE_Y on y with var(v_n) = σ_v²/(1 − ψ²), UPDATE_Z Algorithm 1's (the
    gap kinds are left to the caller). The reference's operations in its order: a sum over one index is
    0 + t₀ + t₁ (``np.einsum``'s); 𝒬's double sum over j, k runs j-major, for one row (G = 1) as the k-sums added
    per j — the order ``np.einsum`` takes for three operands."""
    G = p.shape[0]
    A, Qk, Lam, D, R, M = _empty_tables(n_kinds, G)
    Q, I_LD, I_LH = np.empty((2, 2)), np.empty((2, 2)), np.empty((2, 2))
    Gamma, D_z, Phi, L = np.empty(2), np.empty(2), np.empty(2), np.empty(2)
    for g in range(G):
        sigma_w, sigma_v, psi = p[g, 0], p[g, 1], p[g, 2]
        var_w, var_v = sigma_w * sigma_w, sigma_v * sigma_v
        _plain_row(A, Qk, D, R, g, var_w, var_v / (1.0 - psi * psi), F, BB, H)  # the first y: var(v_n)
        for i in range(2):
            for j in range(2):
                Q[i, j] = BB[i, j] * var_w  # Q = σ_w² B Bᵀ
        for i in range(2):
            Gamma[i] = H_F_inv[i] * psi  # Γ = ψ H F⁻¹ (eq. 5)
            D_z[i] = H[i] - Gamma[i]  # D = H − Γ (eq. 5)
        for i in range(2):
            Phi[i] = 0.0 + Q[i, 0] * Gamma[0] + Q[i, 1] * Gamma[1]  # Φ = Q Γᵀ
        R_bar = (0.0 + Gamma[0] * Phi[0] + Gamma[1] * Phi[1]) + var_v  # R̄ = Γ Φ + σ_v² (eq. 6)
        HPhi_R = (0.0 + H[0] * Phi[0] + H[1] * Phi[1]) + var_v
        for i in range(2):
            L[i] = Phi[i] / HPhi_R  # Λ = Φ (H Φ + σ_v²)⁻¹ (eq. 10)
        for i in range(2):
            for j in range(2):
                eye = 1.0 if i == j else 0.0
                I_LD[i, j], I_LH[i, j] = eye - L[i] * D_z[j], eye - L[i] * H[j]
        for i in range(2):
            for k in range(2):
                A[UPDATE_Z, i, k, g] = 0.0 + I_LD[i, 0] * F[0, k] + I_LD[i, 1] * F[1, k]  # A = (I − Λ D) F (eq. 8)
        for i in range(2):
            for m in range(2):  # 𝒬 = (I − Λ H) Q (I − Λ D)ᵀ (eq. 11)
                q = 0.0
                for j in range(2):
                    if G == 1:
                        q += I_LH[i, j] * Q[j, 0] * I_LD[m, 0] + I_LH[i, j] * Q[j, 1] * I_LD[m, 1]
                    else:
                        q = q + I_LH[i, j] * Q[j, 0] * I_LD[m, 0]
                        q = q + I_LH[i, j] * Q[j, 1] * I_LD[m, 1]
                Qk[UPDATE_Z, i, m, g] = q
        Lam[UPDATE_Z, 0, g], Lam[UPDATE_Z, 1, g] = L[0], L[1]
        D[UPDATE_Z, 0, g], D[UPDATE_Z, 1, g] = D_z[0], D_z[1]
        R[UPDATE_Z, g] = R_bar
    return A, Qk, Lam, D, R, M


def differenced_kinds(kinds: np.ndarray, z: np.ndarray, finite: np.ndarray, y_before: np.ndarray,
                      missed: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`bboxtune.filters.kf_cmn.differenced_kinds` compiled: the frame kinds (C, T) with every finite y_n that has
    an earlier finite y_m made kind UPDATE_Z + i (g = n − m − 1 = ``gaps[i]``: 0, then the other gap lengths, sorted),
    the gaps, every frame's measurement m_n (C, T). ``kinds`` changes in place (int32 beyond 123 gap lengths)."""
    z, psi = np.ascontiguousarray(z, dtype=np.float64), np.ascontiguousarray(psi, dtype=np.float64)
    y_before = np.ascontiguousarray(y_before, dtype=np.float64)
    missed, finite = np.ascontiguousarray(missed, dtype=np.int64), np.ascontiguousarray(finite, dtype=np.bool_)
    present = np.zeros(z.shape[1] + int(missed.max(initial=0)) + 1, np.bool_)
    _differenced(kinds, z, finite, y_before, missed, psi, present, np.zeros(0, np.int64), np.empty((0, 0)))
    lengths = np.flatnonzero(present)
    if UPDATE_Z + len(lengths) > np.iinfo(np.int8).max:
        kinds = kinds.astype(np.int32)
    kind_of_gap = np.zeros(len(present), np.int64)
    kind_of_gap[lengths] = UPDATE_Z + 1 + np.arange(len(lengths))
    m = np.empty(z.shape)
    _differenced(kinds, z, finite, y_before, missed, psi, present, kind_of_gap, m)
    return kinds, np.concatenate([[0], lengths]), m


@jit.kernel
def _differenced(kinds: np.ndarray, z: np.ndarray, finite: np.ndarray, y_before: np.ndarray, missed: np.ndarray,
                 psi: np.ndarray, present: np.ndarray, kind_of_gap: np.ndarray, m: np.ndarray) -> None:
    """One scan of every channel: with an empty ``m``, mark the gap lengths g >= 1 ``present``; else set ``kinds``
    (UPDATE_Z where g = 0, ``kind_of_gap[g]`` across a gap) and the measurements ``m``."""
    C, T = z.shape
    lengths_only = m.shape[0] == 0
    power, power_of = np.empty(len(present)), np.full(len(present), -1)  # ψ^{g+1} of channel power_of[g]
    for c in range(C):
        last = -1  # the last finite frame of this call so far
        for n in range(T):
            if not finite[c, n]:
                if not lengths_only:
                    m[c, n] = 0.0
                continue
            if last >= 0 or not np.isnan(y_before[c]):  # an earlier finite y: in this call, or the carried one
                g = n - last - 1 if last >= 0 else n + missed[c]  # g = n − m − 1
                y_m = z[c, last] if last >= 0 else y_before[c]
                if lengths_only:
                    present[g] |= g > 0
                elif g == 0:
                    kinds[c, n] = UPDATE_Z
                    m[c, n] = z[c, n] - psi[c] * y_m  # (G1), g = 0
                else:
                    if power_of[g] != c:  # one power per channel and gap length
                        power[g], power_of[g] = psi[c] ** (g + 1.0), c
                    kinds[c, n] = kind_of_gap[g]
                    m[c, n] = z[c, n] - power[g] * y_m  # (G1)
            elif not lengths_only:
                m[c, n] = z[c, n]
            last = n


def frame_kinds(finite: np.ndarray, prior: bool | np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
    """:func:`bboxtune.filters.kalman_core.frame_kinds` compiled: the kind (C, T) int8 of every frame from the
    finite-measurement mask ``finite`` (C, T), whether a channel starts from a prior (bool or (C,)) and, in a continued
    run, whether its first finite measurement lies before frame 0 (``measured`` (C,) or None)."""
    C = finite.shape[0]
    seen = np.zeros(C, np.bool_) if measured is None else np.ascontiguousarray(measured, dtype=np.bool_)
    return _frame_kinds(np.ascontiguousarray(finite, dtype=np.bool_), np.broadcast_to(prior, (C,)).astype(np.bool_),
                        seen)


@jit.kernel
def _frame_kinds(finite: np.ndarray, prior: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """WAIT before a channel's first finite measurement without a prior, then INIT there; with a prior or after it,
    UPDATE_Y at finite frames, PREDICT at the others (``seen``: a measurement before frame 0)."""
    C, T = finite.shape
    kinds = np.empty((C, T), np.int8)
    for c in range(C):
        started = seen[c] or prior[c]  # an estimate exists before this frame
        for n in range(T):
            if finite[c, n]:
                kinds[c, n] = UPDATE_Y if started else INIT
                started = True
            else:
                kinds[c, n] = PREDICT if started else WAIT
    return kinds
