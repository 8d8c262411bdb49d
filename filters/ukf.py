"""Unscented Kalman filter (seed 003 Algorithm 1, Wan–van der Merwe scaled sigma points; notes §1.8), batched
over channels, with an optional camera-motion augmented model (seed 003 eq. 17).

Sigma points and weights (seed 003 eq. 1), n = state size of a channel:

    λ = α²(n + κ) − n;  χ_0 = x,  χ_i = x ± [√((n + λ) P)]_i  (Cholesky columns)
    W_0^m = λ/(n + λ),  W_0^c = λ/(n + λ) + 1 − α² + β,  W_i^m = W_i^c = 1/(2(n + λ))

Each frame: predict (eqs. 6–8) χ ← f(χ), x⁻ = Σ W^m χ, P⁻ = Σ W^c (χ − x⁻)(χ − x⁻)ᵀ + Q; the sigma points
are then re-drawn from (x⁻, P⁻) as in filterpy master (fix of filterpy issue #172); update (eqs. 9–12)
Z = h(χ), ẑ = Σ W^m Z, S = Σ W^c (Z − ẑ)(Z − ẑ)ᵀ + R, P_xz = Σ W^c (χ − x⁻)(Z − ẑ)ᵀ, K = P_xz S⁻¹,
x = x⁻ + K (y − ẑ), P = P⁻ − K S Kᵀ. Noise is additive (Q, R added to the transformed covariances) rather
than carried as extra sigma-point dimensions (the augmented x^a of seed 003 eq. 5); for additive noise
both give the same filter on linear models.

The box model is linear, so this UKF equals :class:`filters.kf.KF` up to rounding: at the default
α = 1, β = 2, κ = 0 the tests measure relative differences of 2e-15 with a prior and 6e-13 when starting from
the first measurement (diffuse velocity); tolerance 1e-8. With the small α of seed 003 (1e-3),
W_0^m = 1 − 1/α² ≈ −1e6 and cancellation costs about six digits: 5e-6 absolute on states up to 4.4e3
(1e-9 relative; notes §1.8 found 6.8e-6 on 6.7e3 with filterpy). Against filterpy's
``UnscentedKalmanFilter`` (Merwe points, same α, β, κ) the difference is ~2e-15 relative.

Camera motion (``camera_motion=True``; seed 003 eq. 17)
--------------------------------------------------------
Eq. 17 augments the object state (position x(1,2), velocity x(3,4)) with the image frame's position x(5,6)
and the camera velocity x(7,8). Detections measure the object relative to the frame, so only that
difference is observable; each camera-affected coordinate therefore carries the three states
``[q, r, c]``: image position q = object − frame position, image velocity r = object − frame velocity, and
c = the apparent background velocity (how fast a static scene point moves in the image; −x(7) of eq. 17):

    q_n = q_{n-1} + τ r_{n-1} + (τ²/2)(a_n + a^c_n),  r_n = r_{n-1} + τ (a_n + a^c_n),  c_n = c_{n-1} + τ a^c_n

with object acceleration a ~ N(0, σ_w²) and camera (background) acceleration a^c ~ N(0, σ_c²) (eq. 17 writes
the camera velocity as constant; σ_c lets it drift). Measurements: y_n = q_n + N(0, σ_v²) and, if the caller
supplies it, ``u_n = c_n + N(0, σ_u²)`` — e.g. the global image shift between frames n−1 and n (phase
correlation / background feature flow) divided by τ, in units/s. With u the filter separates a smooth object
motion from camera jitter (test: position RMSE 0.71 vs 1.43 px for the best uncompensated filter, σ_w = 2,
σ_c = 200, σ_v = 2, σ_u = 5); without u, (q, r) follow a constant-velocity model with acceleration variance
σ_w² + σ_c² (c is then unobservable and does not affect the output). As σ_u → 0 the model approaches seed 003
eq. 18 (camera velocity as a known input). Camera states are added to the first min(M, 2) coordinates
(cx, cy), so eq. 17's 8 states become 2 × 3 (the unobservable frame position is not carried); box size
(w, h) is not affected by camera translation. Output is the image state [q, r], like every other filter.

Conventions: predict-first with prior ``x0``/``P0`` (as :class:`filters.kf.KF`); ``x0=None`` initialises at the
first finite y as [y, 0] (c = 0) with covariance P0 or diag(σ_v², (10³σ_v/τ)²) (c variance (10³σ_v/τ)²,
independent of r); frames before that are NaN. NaN in y or u = that measurement is missing (update with the
rest, predict only if nothing is left). ``run_from(y, carry, u)`` continues from the posterior a previous call
ended in (:class:`filters.base.Carry`; with camera_motion its ``c``, ``P_c`` hold the camera state c and its
covariance with [q, r, c]) with this call's parameters.

>>> import numpy as np, filters
>>> f = filters.make("ukf", filters.constant_velocity(0.05, ndim=2), camera_motion=True, sigma_c=5.0)
>>> f.run(np.zeros((4, 2)), u=np.ones((4, 2))).shape
(4, 4)
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from filters.base import AxisCarry, Filter
from filters.kalman_core import INIT, VELOCITY_PRIOR_SCALE, WAIT, channel_start, check_prior, frame_kinds
from filters.validation import as_param, check_positive


class UKF(Filter):
    """Unscented KF. Per-track parameters: ``sigma_w`` (object acceleration noise std, units/s²), ``sigma_v``
    (measurement noise std, units), ``alpha`` (> 0, sigma-point spread), ``beta`` (>= 0, prior-distribution
    weight; 2 is optimal for Gaussians), ``kappa`` (> −2, secondary scaling), ``sigma_c`` (camera acceleration
    noise std, units/s²) and ``sigma_u`` (std of the camera-velocity measurement u, units/s) — the last two only
    with ``camera_motion=True``. Shared: ``x0`` (K,), ``P0`` (K, K), ``camera_motion`` (bool).
    Defaults α = 1, β = 2, κ = 0 (seed 003 suggests α = 1e-3, which costs precision, see module docstring)."""

    name: ClassVar[str] = "ukf"
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "sigma_w": 1.0, "sigma_v": 1.0, "alpha": 1.0, "beta": 2.0, "kappa": 0.0,
        "x0": None, "P0": None, "camera_motion": False, "sigma_c": 1.0, "sigma_u": 1.0,
    }
    PER_TRACK: ClassVar[tuple[str, ...]] = ("sigma_w", "sigma_v", "alpha", "beta", "kappa", "sigma_c", "sigma_u")

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        x0, P0 = check_prior(params["x0"], params["P0"], self.model.K, self.model.M)
        out = {k: check_positive(k, params[k]) for k in ("sigma_w", "sigma_v", "alpha", "sigma_c", "sigma_u")}
        for name, low, text in (("beta", 0.0, ">= 0"), ("kappa", -2.0, "> -2 (n + κ > 0 for n = 2 states)")):
            arr = as_param(name, params[name])
            if not np.all(np.isfinite(arr)) or np.any(arr < low) or (name == "kappa" and np.any(arr == low)):
                raise ValueError(f"{name}={params[name]!r} is out of range: allowed finite values {text}")
            out[name] = arr
        if not isinstance(params["camera_motion"], (bool, np.bool_)):
            raise ValueError(f"camera_motion={params['camera_motion']!r}; allowed: True or False")
        return {**out, "x0": x0, "P0": P0, "camera_motion": bool(params["camera_motion"])}

    @property
    def camera_coordinates(self) -> int:
        """How many leading coordinates carry camera states (0 without ``camera_motion``)."""
        return min(self.model.M, 2) if self.params["camera_motion"] else 0

    def _run_axes_from(self, z: np.ndarray, params: dict[str, Any], start: AxisCarry | None,
                       u: np.ndarray | None) -> tuple[np.ndarray, AxisCarry]:
        """Channels (C, T) → (C, T, 2); camera channels (coordinate < n_c) run the 3-state model."""
        axis, M = self.model.axis(), self.model.M
        C, T = z.shape
        var_v = params["sigma_v"] ** 2
        x_start, P_start, prior = channel_start(params["x0"], params["P0"], M, C, var_v, axis.tau, start)
        kinds = frame_kinds(~np.isnan(z), prior, measured=None if start is None else start.measured)
        camera = np.arange(C) % M < self.camera_coordinates
        F, b = axis.F, axis.B[:, 0]
        out, x_end, P_end = np.empty((C, T, 2)), np.empty((C, 2)), np.empty((C, 2, 2))
        c_end = P_c_end = None
        for group, n in ((~camera, 2), (camera, 3)):
            if not group.any():
                continue
            sw, sc = params["sigma_w"][group], params["sigma_c"][group]
            Fn, Q = F, np.outer(b, b)[:, :, None] * sw**2
            x0, P0 = np.zeros((group.sum(), n)), np.zeros((group.sum(), n, n))
            x0[:, :2], P0[:, :2, :2] = x_start[group], P_start[group]
            meas = z[None, group].transpose(0, 2, 1)
            R = var_v[None, group]
            if n == 3:  # [q, r, c]: eq. 17 in image coordinates (module docstring)
                Fn = np.eye(3)
                Fn[:2, :2] = F
                b_c = np.array([b[0], b[1], b[1]])
                Q = np.pad(Q, ((0, 1), (0, 1), (0, 0))) + np.outer(b_c, b_c)[:, :, None] * sc**2
                P0[:, 2, 2] = VELOCITY_PRIOR_SCALE**2 * var_v[group] / axis.tau**2
                carried = np.zeros(len(x0), dtype=bool) if start is None else ~np.isnan(start.x[group, 0])
                if carried.any():  # continue the camera state c and its covariance with [q, r, c]
                    x0[carried, 2] = start.c[carried]
                    P0[carried, 2, :] = start.P_c[carried]
                    P0[carried, :, 2] = start.P_c[carried]
                if u is not None:
                    meas = np.stack([z[group], u[group]]).transpose(0, 2, 1)
                    R = np.stack([R[0], params["sigma_u"][group] ** 2])
            H = np.eye(n)[[0, 2][: meas.shape[0]]]
            weights = scaled_weights(n, params["alpha"][group], params["beta"][group], params["kappa"][group])
            states, x_last, P_last = unscented_filter(
                meas, kinds[group], lambda s, Fn=Fn: np.einsum("ij,sjc->sic", Fn, s),
                lambda s, H=H: np.einsum("ij,sjc->sic", H, s), Q, R, x0.T, P0.transpose(1, 2, 0), weights)
            out[group] = states[:, :2].transpose(2, 0, 1)
            x_end[group], P_end[group] = x_last[:2].T, P_last[:2, :2].transpose(2, 0, 1)
            if n == 3:
                c_end, P_c_end = x_last[2], P_last[2].T
        waiting = kinds[:, -1] == WAIT  # not started: NaN state (the next call starts it)
        x_end[waiting], P_end[waiting] = np.nan, np.nan
        if c_end is not None:
            c_end[waiting[camera]], P_c_end[waiting[camera]] = np.nan, np.nan
        return out, AxisCarry(x=x_end, P=P_end, c=c_end, P_c=P_c_end)


def scaled_weights(n: int, alpha: np.ndarray, beta: np.ndarray, kappa: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per channel (C,): sigma-point scale n + λ (C,), mean weights W^m (2n+1, C), covariance weights W^c
    (2n+1, C) (seed 003 eq. 1)."""
    lam = alpha**2 * (n + kappa) - n  # λ = α²(n + κ) − n
    spread = n + lam
    Wm = np.repeat((0.5 / spread)[None], 2 * n + 1, axis=0)  # W_i = 1 / (2(n + λ))
    Wm[0] = lam / spread  # W_0^m = λ / (n + λ)
    Wc = Wm.copy()
    Wc[0] += 1.0 - alpha**2 + beta  # W_0^c = λ/(n + λ) + 1 − α² + β
    return spread, Wm, Wc


def matrix_root(A: np.ndarray) -> np.ndarray:
    """A square root L (L Lᵀ = A) of every symmetric matrix in A (n, n, C), channel axis last.

    Lower Cholesky factor (a loop over the n ≤ 3 matrix dimensions, vectorised over channels); channels whose
    matrix is not positive definite (e.g. a singular P0) get the symmetric eigen-square-root instead."""
    n = A.shape[0]
    L = np.zeros_like(A)
    definite = np.ones(A.shape[2], dtype=bool)
    for j in range(n):
        d = A[j, j] - np.sum(L[j, :j] ** 2, axis=0)
        definite &= d > 0
        L[j, j] = np.sqrt(np.where(definite, d, 1.0))
        for i in range(j + 1, n):
            L[i, j] = (A[i, j] - np.sum(L[i, :j] * L[j, :j], axis=0)) / L[j, j]
    if not definite.all():
        w, V = np.linalg.eigh(A[:, :, ~definite].transpose(2, 0, 1))
        L[:, :, ~definite] = (V * np.sqrt(np.clip(w, 0.0, None))[:, None, :]).transpose(1, 2, 0)
    return L


def sigma_points(x: np.ndarray, P: np.ndarray, spread: np.ndarray) -> np.ndarray:
    """χ = [x, x + √((n+λ)P)_i, x − √((n+λ)P)_i] (seed 003 eqs. 1, 6): x (n, C), P (n, n, C) → (2n+1, n, C);
    √ is :func:`matrix_root` and [·]_i its column i."""
    offsets = matrix_root(spread * P).transpose(1, 0, 2)  # row i = column i of the root
    return np.concatenate([x[None], x[None] + offsets, x[None] - offsets], axis=0)


def unscented_transform(chi: np.ndarray, Wm: np.ndarray, Wc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean (d, C), covariance (d, d, C) and deviations (2n+1, d, C) of sigma points ``chi`` (eqs. 3–4, 8)."""
    mean = np.einsum("sc,sdc->dc", Wm, chi)
    dev = chi - mean[None]
    return mean, np.einsum("sc,sic,sjc->ijc", Wc, dev, dev), dev


def unscented_filter(y: np.ndarray, kinds: np.ndarray, fx: Any, hx: Any, Q: np.ndarray, R: np.ndarray,
                     x_start: np.ndarray, P_start: np.ndarray, weights: tuple[np.ndarray, ...]) -> np.ndarray:
    """Batched UKF over C channels (channel axis last): measurements ``y`` (p, T, C) with NaN = missing (row 0
    decides the frame ``kinds`` (C, T) of :func:`filters.kalman_core.frame_kinds`), ``fx``/``hx`` map sigma
    points (S, n, C) to (S, n, C)/(S, p, C), ``Q`` (n, n, C), ``R`` (p, C) diagonal measurement variances,
    start state/covariance (n, C)/(n, n, C), ``weights`` from :func:`scaled_weights`.
    Returns posterior states (T, n, C) (NaN at WAIT frames) and the posterior state (n, C) and covariance
    (n, n, C) at the last frame (the start values for a channel still waiting there)."""
    p, T, C = y.shape
    spread, Wm, Wc = weights
    x, P = x_start.copy(), P_start.copy()
    out = np.empty((T, x.shape[0], C))
    observed = ~np.isnan(y)
    y0 = np.where(observed, y, 0.0)
    R_diag = R[:, None] * np.eye(p)[:, :, None]
    for n in range(T):
        x, P, _ = unscented_transform(fx(sigma_points(x, P, spread)), Wm, Wc)  # eqs. 7–8
        P += Q
        obs = observed[:, n].copy()
        kind = kinds[:, n]
        if np.any(kind <= INIT):  # WAIT: keep the start values; INIT: start at [y, 0, …], use only the rest of y
            reset = kind <= INIT
            x[:, reset], P[:, :, reset] = x_start[:, reset], P_start[:, :, reset]
            x[0, kind == INIT] = y0[0, n, kind == INIT]
            obs[0, reset] = False
            obs[:, kind == WAIT] = False
        if obs.any():
            chi = sigma_points(x, P, spread)  # re-drawn from (x⁻, P⁻)
            z_hat, _, dz = unscented_transform(hx(chi), Wm, Wc)  # eq. 9
            dz = np.where(obs[None], dz, 0.0)  # missing components: no innovation, K column 0
            S = np.einsum("sc,sic,sjc->ijc", Wc, dz, dz) + R_diag  # eq. 10
            Pxz = np.einsum("sc,sic,sjc->ijc", Wc, chi - x[None], dz)  # eq. 10
            if p == 1:
                K = Pxz / S[0, 0]  # K = P_xz S⁻¹ (eq. 12)
            else:
                K = np.linalg.solve(S.transpose(2, 0, 1), Pxz.transpose(2, 1, 0)).transpose(2, 1, 0)  # S symmetric
            innovation = np.where(obs, y0[:, n] - z_hat, 0.0)
            x = x + np.einsum("ijc,jc->ic", K, innovation)  # eq. 11
            P = P - np.einsum("ijc,jkc,lkc->ilc", K, S, K)  # eq. 11
            P = 0.5 * (P + P.transpose(1, 0, 2))
        out[n] = x
    return np.where((kinds.T == WAIT)[:, None], np.nan, out), x, P
