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

Conventions
-----------
* Frame 0 (generally: the first finite measurement) has no z. With a prior ``x0``/``P0`` (predict-first, as
  in :class:`filters.kf.KF`) it is a standard KF update on y with the stationary CMN variance
  ``σ_v² / (1 − ψ²)``; without a prior the state is initialised there as ``[y, 0]`` with covariance ``P0``
  or ``diag(σ_v²/(1−ψ²), (10³ σ_v/τ)²/(1−ψ²))``. Frames before it are NaN.
* Later frames use z_n. A missing y_n or y_{n-1} (NaN) means no z_n: that frame is predict-only (x = F x,
  P = F P Fᵀ + Q), so after a gap the first finite y is only used through the next z.
* ψ = 0 gives Γ = 0, Λ = 0, A = F, 𝒬 = Q, D = H, R̄ = σ_v², z = y: bit-identical to ``kf`` on data
  without gaps (with gaps ``kf`` also updates on the first y after a gap, which has no z here).
* Output: posterior ``[positions, velocities]`` at every frame, float64.
* ``run_from(y, carry)`` continues from the posterior state and covariance a previous call ended in
  (:class:`filters.base.Carry`) with this call's σ_w, σ_v, ψ; the carried last measurement y_{-1} gives the
  first frame's ``z_0 = y_0 − ψ y_{-1}`` (ψ of this call), so the split run equals the whole one.

>>> import numpy as np, filters
>>> f = filters.make("kf_cmn", filters.constant_velocity(0.05), sigma_w=50.0, sigma_v=4.0, psi=0.6)
>>> f.run(np.zeros((5, 1))).shape
(5, 2)
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from filters.base import AxisCarry, Filter
from filters.kalman_core import (UPDATE_Z, FramePrior, StepTables, channel_start, check_prior, filter_channels,
                                 frame_kinds, plain_tables)
from filters.model import StateSpaceModel
from filters.validation import check_sigma, check_psi


class KFCMN(FramePrior, Filter):
    """KF for CMN. Parameters: ``sigma_w`` (acceleration noise std, units/s²), ``sigma_v`` (std σ_ξ of the
    white noise driving the CMN, units), ``psi`` (coloredness 0 <= ψ <= 0.99) — all per track — and the prior
    ``x0`` (K,), ``P0`` (K, K) (see module docstring); valid ranges in :mod:`filters.validation`."""

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
        previous = np.empty_like(z)
        previous[:, 0] = np.nan if start is None else start.y_last  # y_{-1}: the carried last measurement
        previous[:, 1:] = z[:, :-1]
        finite = ~np.isnan(z)
        kinds = frame_kinds(finite, prior, differenced=True, measured=None if start is None else start.measured,
                            finite_before=~np.isnan(previous[:, 0]))
        differenced = z - psi[:, None] * previous  # z_n = y_n − ψ y_{n-1} (eq. 4)
        m = np.where(kinds == UPDATE_Z, differenced, np.where(finite, z, 0.0))
        row_params = np.stack([params["sigma_w"], params["sigma_v"], psi], axis=1)
        states, P_end = filter_channels(m, kinds, row_params, x_start, P_start, lambda p: cmn_tables(axis, p))
        return states, AxisCarry(x=states[:, -1], P=P_end)


def cmn_tables(axis: StateSpaceModel, p: np.ndarray) -> StepTables:
    """Step tables of G rows ``p`` = [σ_w, σ_v, ψ] (G, 3): standard KF kinds plus the de-correlated
    UPDATE_Z step of [Shmaliy-CMN] Algorithm 1 (matrices stored row-last, (2, 2, G))."""
    sigma_w, sigma_v, psi = p.T
    F, H, I = axis.F[:, :, None], axis.H[0][:, None], np.eye(2)[:, :, None]
    Q = (axis.B @ axis.B.T)[:, :, None] * sigma_w**2  # Q = σ_w² B Bᵀ
    R = sigma_v**2  # R = σ_ξ²
    tables = plain_tables(axis.F, Q, R / (1.0 - psi**2), axis.H[0])  # frames without z: update on y, var(v_n)
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
