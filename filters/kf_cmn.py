"""Kalman filter for Gauss–Markov coloured measurement noise ([Shmaliy-CMN] Algorithm 1: backward Euler,
measurement differencing, de-correlated noise sources), batched.

Model per coordinate ([Shmaliy-CMN] eqs. 1–3): ``x_n = F x_{n-1} + B w_n``, ``v_n = ψ v_{n-1} + ξ_n``,
``y_n = H x_n + v_n`` with ``Q = σ_w² B Bᵀ`` and ``ξ_n ~ N(0, σ_v²)`` (σ_v is the paper's σ_ξ).
The differenced measurement ``z_n = y_n − ψ y_{n-1} = D x_n + v̄_n`` (eqs. 4–5) has white noise v̄_n that is
correlated with w_n (eqs. 6–7); Algorithm 1 de-correlates them (eqs. 8–11):

    Γ = ψ H F⁻¹,  D = H − Γ,  Φ = Q Γᵀ,  R̄ = Γ Φ + σ_v²                       (5), (6)
    Λ = Φ (H Φ + σ_v²)⁻¹,  A = (I − Λ D) F,  𝒬 = (I − Λ H) Q (I − Λ D)ᵀ        (10), (8), (11)
    x⁻ = A x + Λ z_n,  P⁻ = A P Aᵀ + 𝒬,  S = D P⁻ Dᵀ + R̄,  K = P⁻ Dᵀ S⁻¹,
    x = x⁻ + K (z_n − D x⁻),  P = (I − K D) P⁻ (I − K D)ᵀ + K R̄ Kᵀ           (Alg. 1 lines 5–10)

(Joseph form for line 10; identical for the optimal K.) Derivation check: substituting ``x_n = F x_{n-1} +
B w_n`` into ``0 = z_n − D x_n − v̄_n`` gives eq. 8 with ζ = (I − ΛD) B w − Λ v̄, and E{ζ v̄ᵀ} = 0 ⇔ eq. 10
(using D + Γ = H). The notes (§1.4) verify an equivalent de-correlated form with Λ' = M R̄⁻¹ and
A' = (I + Λ' D)⁻¹; both give the optimal filter of the time-correlated form (filterpy ``update_correlated``
with H = D, R = R̄, M = Q Γᵀ), which the tests use as the oracle.

Across missing frames (derivation and checks: docs/notes/kf-cmn-gaps.md): with y_m the last finite measurement and
g = n − m − 1 >= 1 frames missing between, the difference spans the gap; from x_n = F^{g+1} x_m + w_g,
v_n − ψ^{g+1} v_m = e_n = Σ_{k=0}^{g} ψ^k ξ_{n−k} and F = I + N, N² = 0 (constant velocity: F^k = I + k N):

    z_n = y_n − ψ^{g+1} y_m = D_g x_n + v̄_n,   v̄_n = Γ_g w_g + e_n                                   (G1)
    Q_g = Σ_{j=0}^{g} F^j Q F^jᵀ = (g+1) Q + s₁ (N Q + Q Nᵀ) + s₂ N Q Nᵀ,  s₁ = Σ_{j<=g} j, s₂ = Σ j²   (G2)
    Γ_g = ψ^{g+1} H F^{−(g+1)},  D_g = H − Γ_g                                                        (G3)
    σ_g² = var(e_n) = σ_v² (1 − ψ^{2(g+1)}) / (1 − ψ²)                                                (G4)
    M_g = E{w_g v̄_nᵀ} = Q_g Γ_gᵀ,  R̄_g = Γ_g Q_g Γ_gᵀ + σ_g²                                          (G5)

The g frames between are predict-only, so P⁻ = F P_{n-1} Fᵀ + Q = F^{g+1} P_m F^{g+1}ᵀ + Q_g is the prior of that
model (x⁻ = F x_{n-1}), and frame n is the time-correlated update (filterpy ``update_correlated``, H = D_g,
R = R̄_g, M = M_g):

    S = D_g P⁻ D_gᵀ + D_g M_g + M_gᵀ D_gᵀ + R̄_g,  K = (P⁻ D_gᵀ + M_g) S⁻¹,  x = x⁻ + K (z_n − D_g x⁻)    (G6)
    P = (I − K D_g) P⁻ (I − K D_g)ᵀ + K R̄_g Kᵀ − (I − K D_g) M_g Kᵀ − K M_gᵀ (I − K D_g)ᵀ             (G7)

g = 0 gives z_n, D, R̄, M = Q Γᵀ of Algorithm 1, which the de-correlated form above implements. Across a gap
the de-correlated form written from frame n − 1 (Λ_g = M_g (H M_g + σ_g²)⁻¹, A_g = (I − Λ_g D_g) F,
𝒬_g = (I − Λ_g D_g) Q (I − Λ_g D_g)ᵀ − R̄_g Λ_g Λ_gᵀ) is the same filter, but it must cancel the gap's process noise
out of P_{n-1}: at σ_w τ²/σ_v = 1e20 the velocity after a 30-frame gap at ψ = 0.3 came out 33 % wrong, where
(G6)–(G7) stay within 3e-13 of a 40-digit reference (ratios 1e-12 … 1e50, ψ 0.3 … 0.99).

Conventions
-----------
* The first finite measurement of a channel has no z. With a prior ``x0``/``P0`` (predict-first, as in
  :class:`bboxtune.filters.kf.KF`) it is a standard KF update on y with the stationary CMN variance ``σ_v² / (1 − ψ²)``;
  without a prior the state is initialised there as ``[y, 0]`` with covariance ``P0`` or
  ``diag(σ_v²/(1−ψ²), (10³ σ_v/τ)²/(1−ψ²))``. Frames before it are NaN.
* Every later finite y_n updates on z_n of (G1), across any gap; a missing y_n is predict-only (x = F x,
  P = F P Fᵀ + Q). (Until issue 33 the first y after a gap was predict-only too, which dropped one measurement
  per gap: at ψ = 0 it was up to 47 px off the KF on a track with 57 % of its frames missing.)
* ψ = 0 gives Γ = Γ_g = 0, Λ = 0, A = F, 𝒬 = Q, D = D_g = H, R̄ = R̄_g = σ_v², M_g = 0, z = y: bit-identical
  to ``kf`` on any missing pattern.
* Output: posterior ``[positions, velocities]`` at every frame, float64.
* ``run_from(y, carry)`` continues from the posterior state and covariance a previous call ended in
  (:class:`bboxtune.filters.base.Carry`) with this call's σ_w, σ_v, ψ; the carried last finite measurement and the frames
  missed since (``Carry.y_last``, ``Carry.missed``) give the first z of the call (ψ of this call), so a run
  split anywhere, inside gaps too, equals the whole one. A measured coordinate whose carry has no finite
  ``y_last`` (a hand-made carry) updates its next finite y like a first measurement with a prior.
* Speed: every gap length present in a call is one more frame kind (``UPDATE_Z + i`` for ``gaps[i]``,
  :func:`differenced_kinds`) whose table entries (:func:`gap_update`) are built once for all rows; gap-free data
  has the one kind UPDATE_Z and costs what it did before (about 1 % more instructions).

>>> import numpy as np
>>> from bboxtune import filters
>>> f = filters.make("kf_cmn", filters.constant_velocity(0.05), sigma_w=50.0, sigma_v=4.0, psi=0.6)
>>> f.run(np.zeros((5, 1))).shape
(5, 2)
"""

from __future__ import annotations

from typing import Any, ClassVar, cast

import numpy as np

from bboxtune.filters import jit, kalman_kernels
from bboxtune.filters.base import AxisCarry, Filter
from bboxtune.filters.kalman_core import (
    UPDATE_Z,
    FramePrior,
    StepTables,
    channel_start,
    filter_channels,
    frame_kinds,
    plain_tables,
)
from bboxtune.filters.kf import TABLES, axis_matrices
from bboxtune.filters.model import StateSpaceModel
from bboxtune.filters.validation import check_prior, check_psi, check_sigma


class KFCMN(FramePrior, Filter):
    """KF for CMN. Parameters: ``sigma_w`` (acceleration noise std, units/s²), ``sigma_v`` (std σ_ξ of the
    white noise driving the CMN, units), ``psi`` (coloredness 0 <= ψ <= 0.99) — all per track — and the prior
    ``x0`` (K,), ``P0`` (K, K) (see module docstring); valid ranges in :mod:`bboxtune.filters.validation`."""

    name: ClassVar[str] = "kf_cmn"
    DEFAULTS: ClassVar[dict[str, Any]] = {"sigma_w": 1.0, "sigma_v": 1.0, "psi": 0.0, "x0": None, "P0": None}
    PER_TRACK: ClassVar[tuple[str, ...]] = ("sigma_w", "sigma_v", "psi")

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        sigma_v = check_sigma("sigma_v", params["sigma_v"])
        x0, P0 = check_prior(params["x0"], params["P0"], self.model.K, self.model.M, sigma_v, self.model.tau)
        return {"sigma_w": check_sigma("sigma_w", params["sigma_w"]), "sigma_v": sigma_v,
                "psi": check_psi(params["psi"]), "x0": x0, "P0": P0}

    def _run_axes_from(self, z: np.ndarray, params: dict[str, Any], start: AxisCarry | None,
                       u: np.ndarray | None) -> tuple[np.ndarray, AxisCarry]:
        axis = self.model.axis()
        psi = params["psi"]
        var_y = params["sigma_v"] ** 2 / (1.0 - psi**2)  # stationary variance of v_n
        x_start, P_start, prior = channel_start(params["x0"], params["P0"], self.model.M, z.shape[0], var_y,
                                                axis.tau, start)
        finite = ~np.isnan(z)
        kinds = frame_kinds(finite, prior, measured=None if start is None else start.measured)
        if start is None:
            y_before, missed = np.full(len(z), np.nan), np.zeros(len(z), np.int64)
        else:
            y_before, missed = cast(np.ndarray, start.y_last), cast(np.ndarray, start.missed)  # set in a given start
        difference = kalman_kernels.differenced_kinds if jit.enabled() else differenced_kinds
        kinds, gaps, m = difference(kinds, z, finite, y_before, missed, psi)
        row_params = np.stack([params["sigma_w"], params["sigma_v"], psi], axis=1)
        states, P_end = filter_channels(m, kinds, row_params, x_start, P_start, lambda p: TABLES.get(
            ("kf_cmn", axis.F.tobytes(), axis.B.tobytes(), gaps.tobytes(), p), lambda: cmn_tables(axis, p, gaps)))
        return states, AxisCarry(x=states[:, -1], P=P_end)


def differenced_kinds(kinds: np.ndarray, z: np.ndarray, finite: np.ndarray, y_before: np.ndarray,
                      missed: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame kinds (C, T) of :func:`bboxtune.filters.kalman_core.frame_kinds` with every finite y_n that has an earlier finite
    y_m — in ``z`` (C, T) or the carried ``y_before`` (C,) (NaN: none) with ``missed`` (C,) frames after it — made
    kind ``UPDATE_Z + i``, g = n − m − 1 = ``gaps[i]`` (``gaps`` (n,): 0, then the other gap lengths present, sorted);
    the gaps, and every frame's measurement m_n (C, T): z_n = y_n − ψ^{g+1} y_m (G1) there, else y_n (0 if NaN)."""
    T = z.shape[1]
    previous = np.empty_like(z)  # y_{n−1}; frame 0: the carried y if it was the last frame's
    previous[:, 0] = np.where(missed == 0, y_before, np.nan)
    previous[:, 1:] = z[:, :-1]
    differenced = finite & ~np.isnan(previous)  # g = 0
    m = np.where(differenced, z - psi[:, None] * previous, np.where(finite, z, 0.0))  # (G1), g = 0
    kinds[differenced] = UPDATE_Z
    rows, frames = np.nonzero(finite & ~differenced)  # the first finite y of a run: of the channel, or after a gap
    later = np.r_[False, rows[1:] == rows[:-1]] | differenced[rows, 0]  # a finite y of this call lies before it
    spans = later | ~np.isnan(y_before[rows])  # else y_m is the carried y (m = −1 − missed) or there is none
    if not spans.any():
        return kinds, np.zeros(1, np.int64), m
    rows, frames, later = rows[spans], frames[spans], later[spans]
    before = np.full(len(rows), -1)  # m, the last finite frame before n (rows with a finite y before it)
    involved, at = np.unique(rows[later], return_inverse=True)
    last = np.maximum.accumulate(np.where(finite[involved], np.arange(T), -1), axis=1)
    before[later] = last[at.ravel(), frames[later] - 1]
    gap = np.where(later, frames - before - 1, frames + missed[rows])  # g = n − m − 1 >= 1
    y_m = np.where(later, z[rows, before], y_before[rows])
    m[rows, frames] = z[rows, frames] - psi[rows] ** (gap + 1.0) * y_m  # (G1)
    lengths, index = np.unique(gap, return_inverse=True)
    if UPDATE_Z + len(lengths) > np.iinfo(np.int8).max:
        kinds = kinds.astype(np.int32)
    kinds[rows, frames] = UPDATE_Z + 1 + index.ravel()
    return kinds, np.concatenate([[0], lengths]), m


def cmn_tables(axis: StateSpaceModel, p: np.ndarray, gaps: np.ndarray) -> StepTables:
    """Step tables of G rows ``p`` = [σ_w, σ_v, ψ] (G, 3): the KF kinds WAIT … UPDATE_Y (the first measurement:
    an update on y with var(v_n) = σ_v²/(1 − ψ²)), then per gap length ``gaps[i]`` (n,) the kind UPDATE_Z + i:
    [Shmaliy-CMN] Algorithm 1 for gaps[0] = 0, the time-correlated update (G6) across a gap (matrices row-last).
    All but the gap kinds come from the compiled :func:`bboxtune.filters.kalman_kernels.cmn_tables` where
    :func:`bboxtune.filters.jit.enabled` (bit for bit :func:`cmn_tables_numpy`'s, in ~2 µs instead of ~0.2 ms for
    one row), else from :func:`cmn_tables_numpy`."""
    n_kinds = UPDATE_Z + len(gaps)
    if jit.enabled():
        F, BB, H, H_F_inv = axis_matrices(axis)
        tables = StepTables(*kalman_kernels.cmn_tables(np.ascontiguousarray(p, dtype=np.float64), F, BB, H, H_F_inv,
                                                       n_kinds))
    else:
        tables = cmn_tables_numpy(axis, p, n_kinds)
    if len(gaps) > 1:  # across g >= 1 missing frames: predict with (F, Q), the time-correlated update (G6)
        sigma_w, sigma_v, psi = p.T
        D_g, R_g, M_g = gap_update(axis, sigma_w, sigma_v, psi, np.asarray(gaps[1:], dtype=float))
        tables.D[UPDATE_Z + 1:], tables.R[UPDATE_Z + 1:], tables.M[UPDATE_Z + 1:] = D_g, R_g, M_g
    return tables


def cmn_tables_numpy(axis: StateSpaceModel, p: np.ndarray, n_kinds: int) -> StepTables:
    """The tables of :func:`cmn_tables` in numpy (the reference) with ``n_kinds`` kinds, all but the gap kinds
    UPDATE_Z + 1 … filled in."""
    sigma_w, sigma_v, psi = p.T
    F, H, I = axis.F[:, :, None], axis.H[0][:, None], np.eye(2)[:, :, None]
    Q = (axis.B @ axis.B.T)[:, :, None] * sigma_w**2  # Q = σ_w² B Bᵀ
    R = sigma_v**2  # R = σ_ξ²
    tables = plain_tables(axis.F, Q, R / (1.0 - psi**2), axis.H[0], n_kinds)  # first y: var(v_n)
    Gamma = (axis.H[0] @ np.linalg.inv(axis.F))[:, None] * psi  # Γ = ψ H F⁻¹ (eq. 5)
    D = H - Gamma  # D = H − Γ (eq. 5)
    Phi = np.einsum("ijg,jg->ig", Q, Gamma)  # Φ = B Q Bᵀ Γᵀ (below eq. 7)
    R_bar = np.einsum("ig,ig->g", Gamma, Phi) + R  # R̄ = Γ Φ + R (eq. 6)
    Lam = Phi / (np.einsum("ig,ig->g", H, Phi) + R)  # Λ = Φ (H Φ + R)⁻¹ (eq. 10)
    I_LD = I - Lam[:, None] * D[None]
    A = np.einsum("ijg,jkg->ikg", I_LD, F)  # A = (I − Λ D) F (eq. 8)
    Q_dec = np.einsum("ijg,jkg,lkg->ilg", I - Lam[:, None] * H[None], Q, I_LD)  # (I − ΛH) Q (I − ΛD)ᵀ (eq. 11)
    tables.A[UPDATE_Z] = A
    tables.Q[UPDATE_Z] = Q_dec
    tables.Lam[UPDATE_Z] = Lam
    tables.D[UPDATE_Z] = D
    tables.R[UPDATE_Z] = R_bar
    return tables


def gap_update(axis: StateSpaceModel, sigma_w: np.ndarray, sigma_v: np.ndarray, psi: np.ndarray,
               g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The time-correlated update of z_n = y_n − ψ^{g+1} y_m across g (n,) missing frames for rows [σ_w, σ_v, ψ]
    (G,) each: its observation row D_g (n, 2, G), noise variance R̄_g (n, G) and noise cross-covariance
    M_g = Q_g Γ_gᵀ (n, 2, G), eqs. (G2)–(G5) of docs/notes/kf-cmn-gaps.md."""
    g = g[:, None]  # (n, 1): gaps along the first axis, rows along the last
    N = axis.F - np.eye(2)  # F = I + N, N² = 0: F^k = I + k N (constant velocity)
    BB = axis.B @ axis.B.T
    s1, s2 = g * (g + 1) / 2, g * (g + 1) * (2 * g + 1) / 6  # Σ_{j=1}^{g} j, Σ_{j=1}^{g} j²
    # Q_g = Σ_{j=0}^{g} F^j Q F^jᵀ = (g + 1) Q + s1 (N Q + Q Nᵀ) + s2 N Q Nᵀ (G2); (n, G, 2, 2)
    Q_g = ((g + 1)[..., None, None] * BB + s1[..., None, None] * (N @ BB + BB @ N.T)
           + s2[..., None, None] * (N @ BB @ N.T)) * (sigma_w**2)[:, None, None]
    psi_g = psi ** (g + 1)  # ψ^{g+1} (n, G)
    Gamma = (axis.H[0] - (g + 1)[..., None] * (axis.H[0] @ N)) * psi_g[..., None]  # Γ_g = ψ^{g+1} H F^{−(g+1)} (G3)
    D = axis.H[0] - Gamma  # D_g = H − Γ_g (G3)
    var_e = sigma_v**2 * ((1.0 - psi_g**2) / (1.0 - psi**2))  # σ_g² = σ_v² Σ_{k=0}^{g} ψ^{2k} (G4)
    M = np.einsum("ngij,ngj->ngi", Q_g, Gamma)  # M_g = Q_g Γ_gᵀ = E{w_g v̄ᵀ} (G5)
    R_bar = np.einsum("ngi,ngi->ng", Gamma, M) + var_e  # R̄_g = Γ_g Q_g Γ_gᵀ + σ_g² (G5)
    return D.transpose(0, 2, 1), R_bar, M.transpose(0, 2, 1)
