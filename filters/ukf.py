"""Unscented Kalman filter ([Raj-UKF] Algorithm 1, Wan–van der Merwe scaled sigma points; notes §1.8), batched
over channels, with an optional camera-motion augmented model ([Raj-UKF] eq. 17).

Sigma points and weights ([Raj-UKF] eq. 1), n = state size of a channel:

    λ = α²(n + κ) − n;  χ_0 = x,  χ_i = x ± [√((n + λ) P)]_i  (Cholesky columns)
    W_0^m = λ/(n + λ),  W_0^c = λ/(n + λ) + 1 − α² + β,  W_i^m = W_i^c = 1/(2(n + λ))

Each frame: predict (eqs. 6–8) χ ← f(χ), x⁻ = Σ W^m χ, P⁻ = Σ W^c (χ − x⁻)(χ − x⁻)ᵀ + Q; the sigma points
are then re-drawn from (x⁻, P⁻) as in filterpy master (fix of filterpy issue #172); update (eqs. 9–12)
Z = h(χ), ẑ = Σ W^m Z, S = Σ W^c (Z − ẑ)(Z − ẑ)ᵀ + R, P_xz = Σ W^c (χ − x⁻)(Z − ẑ)ᵀ, K = P_xz S⁻¹,
x = x⁻ + K (y − ẑ), P = P⁻ − K S Kᵀ. Noise is additive (Q, R added to the transformed covariances) rather
than carried as extra sigma-point dimensions (the augmented x^a of [Raj-UKF] eq. 5); for additive noise
both give the same filter on linear models.

Linear model, computed as such. f and h are linear here (f = F, h = H) and the sigma points are symmetric about
their centre, so their weighted means are exactly x⁻ = F x and ẑ = H x⁻; the code uses those exact means and
passes only the covariances through the sigma points, drawn around 0 (χ_0 = 0, χ_i = ±[√((n + λ) P)]_i, with
n + λ computed as α²(n + κ)). Deviations from the exact mean make χ_0's deviation zero, so β (and W_0^c) has no
effect on this linear model. A generic UKF instead forms Σ W^m χ around x, adding rounding of order
eps·|W_i|·‖√P‖ to the means — 2e4 px of error on a 200 px track with σ_v = 1e20, ~1e-9 relative with [Raj-UKF]'s
α = 1e-3 (W_0^m ≈ −1e6), all digits at per-frame noise ratios σ_w τ²/σ_v beyond 1e14 or for κ next to −2.
The covariance recursion does not depend on the data, so — as for :class:`bboxtune.filters.kf.KF`
(:mod:`bboxtune.filters.kalman_core`) — it runs once per unique (parameters, prior, frame kinds) row until its steady state
(the posterior covariance repeats bit for bit), and every frame is the affine map x_n = (I − K_n H) F x_{n−1} +
K_n y_n applied to all channels at once (:func:`sigma_gain_recursion`, a compiled kernel in
:mod:`bboxtune.filters.ukf_kernels`; T = 1e6 frames in ~2 s instead of ~230 s);
the camera-motion channels (3 states, 2 measurements) run the same linear UKF frame by frame
(:func:`unscented_filter`). This UKF equals :class:`bboxtune.filters.kf.KF` to rounding for every α, β, κ in range (tests:
1e-12 relative) and over the whole parameter range of :mod:`bboxtune.filters.validation` (position error against a
40-digit reference <= 3e-13 relative for noise ratios from 1e-12 to 1e100).

Camera motion (``camera_motion=True``; [Raj-UKF] eq. 17)
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
σ_w² + σ_c² (c is then unobservable and does not affect the output). As σ_u → 0 the model approaches [Raj-UKF]
eq. 18 (camera velocity as a known input). Camera states are added to the first min(M, 2) coordinates
(cx, cy), so eq. 17's 8 states become 2 × 3 (the unobservable frame position is not carried); box size
(w, h) is not affected by camera translation. Output is the image state [q, r], like every other filter.

Conventions: predict-first with prior ``x0``/``P0`` (as :class:`bboxtune.filters.kf.KF`); ``x0=None`` initialises at the
first finite y as [y, 0] (c = 0) with covariance P0 or diag(σ_v², (10³σ_v/τ)²) (c variance (10³σ_v/τ)²,
independent of r); frames before that are NaN. NaN in y or u = that measurement is missing (update with the
rest, predict only if nothing is left). ``run_from(y, carry, u)`` continues from the posterior a previous call
ended in (:class:`bboxtune.filters.base.Carry`; with camera_motion its ``c``, ``P_c`` hold the camera state c and its
covariance with [q, r, c]) with this call's parameters.

>>> import numpy as np
>>> from bboxtune import filters
>>> f = filters.make("ukf", filters.constant_velocity(0.05, ndim=2), camera_motion=True, sigma_c=5.0)
>>> f.run(np.zeros((4, 2)), u=np.ones((4, 2))).shape
(4, 4)
"""

from __future__ import annotations

from typing import Any, ClassVar, cast

import numpy as np

from bboxtune.filters import jit, ukf_kernels
from bboxtune.filters.base import AxisCarry, Filter
from bboxtune.filters.kalman_core import (
    INIT,
    UPDATE_Y,
    VELOCITY_PRIOR_SCALE,
    WAIT,
    channel_start,
    filter_channels,
    frame_kinds,
)
from bboxtune.filters.model import StateSpaceModel
from bboxtune.filters.validation import check_prior, check_range, check_sigma

SCALING_RANGES = {"alpha": (1e-4, 1e4, False), "beta": (0.0, 1e4, False), "kappa": (-2.0, 1e4, True)}  # open low


class UKF(Filter):
    """Unscented KF. Per-track parameters: ``sigma_w`` (object acceleration noise std, units/s²), ``sigma_v``
    (measurement noise std, units), ``alpha`` (1e-4 <= α <= 1e4, sigma-point spread), ``beta`` (0 <= β <= 1e4,
    prior-distribution weight; 2 is optimal for Gaussians), ``kappa`` (−2 < κ <= 1e4, secondary scaling: n + κ > 0
    for n = 2 states), ``sigma_c`` (camera acceleration noise std, units/s²) and ``sigma_u`` (std of the
    camera-velocity measurement u, units/s) — the last two only with ``camera_motion=True``. Shared: ``x0`` (K,),
    ``P0`` (K, K), ``camera_motion`` (bool). σ's within :data:`bboxtune.filters.validation.SIGMA_RANGE`.
    Defaults α = 1, β = 2, κ = 0 ([Raj-UKF] suggests α = 1e-3; any α in range is accurate, module docstring)."""

    name: ClassVar[str] = "ukf"
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "sigma_w": 1.0, "sigma_v": 1.0, "alpha": 1.0, "beta": 2.0, "kappa": 0.0,
        "x0": None, "P0": None, "camera_motion": False, "sigma_c": 1.0, "sigma_u": 1.0,
    }
    PER_TRACK: ClassVar[tuple[str, ...]] = ("sigma_w", "sigma_v", "alpha", "beta", "kappa", "sigma_c", "sigma_u")

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        out = {k: check_sigma(k, params[k]) for k in ("sigma_w", "sigma_v", "sigma_c", "sigma_u")}
        x0, P0 = check_prior(params["x0"], params["P0"], self.model.K, self.model.M, out["sigma_v"], self.model.tau)
        for name, (low, high, open_low) in SCALING_RANGES.items():
            out[name] = check_range(name, params[name], low, high, low_open=open_low)
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
        finite = ~np.isnan(z)
        kinds = frame_kinds(finite, prior, measured=None if start is None else start.measured)
        camera = np.arange(C) % M < self.camera_coordinates
        out, x_end, P_end = np.empty((C, T, 2)), np.empty((C, 2)), np.empty((C, 2, 2))
        c_end = P_c_end = None
        plain: np.ndarray | slice = ~camera if camera.any() else slice(None)  # all channels: views, not copies
        if C and self.camera_coordinates < M:  # the two-state model: gains once per row, then affine maps (kalman_core)
            rows = np.stack([params[k][plain] for k in ("sigma_w", "sigma_v", "alpha", "beta", "kappa")], axis=1)
            out[plain], P_end[plain] = filter_channels(
                np.where(finite, z, 0.0)[plain], kinds[plain], rows, x_start[plain], P_start[plain],
                recursion=lambda k, p, P: sigma_gain_recursion(k, p, P, axis))
            x_end[plain] = out[plain, -1]
        if camera.any():  # [q, r, c]: eq. 17 in image coordinates (module docstring), frame by frame
            n_cam = int(camera.sum())
            b = axis.B[:, 0]
            Fn = np.eye(3)
            Fn[:2, :2] = axis.F
            b_c = np.array([b[0], b[1], b[1]])
            Q = (np.pad(np.outer(b, b)[:, :, None] * params["sigma_w"][camera] ** 2, ((0, 1), (0, 1), (0, 0)))
                 + np.outer(b_c, b_c)[:, :, None] * params["sigma_c"][camera] ** 2)
            x0, P0 = np.zeros((n_cam, 3)), np.zeros((n_cam, 3, 3))
            x0[:, :2], P0[:, :2, :2] = x_start[camera], P_start[camera]
            P0[:, 2, 2] = VELOCITY_PRIOR_SCALE**2 * var_v[camera] / axis.tau**2
            carried = np.zeros(n_cam, dtype=bool) if start is None else ~np.isnan(start.x[camera, 0])
            if start is not None and carried.any():  # continue the camera state c and its covariance with [q, r, c]
                c, P_c = cast(np.ndarray, start.c), cast(np.ndarray, start.P_c)  # a camera filter's carry has both
                x0[carried, 2] = c[carried]
                P0[carried, 2, :] = P_c[carried]
                P0[carried, :, 2] = P_c[carried]
            meas, R = z[None, camera].transpose(0, 2, 1), var_v[None, camera]
            if u is not None:
                meas = np.stack([z[camera], u[camera]]).transpose(0, 2, 1)
                R = np.stack([R[0], params["sigma_u"][camera] ** 2])
            H = np.eye(3)[[0, 2][: meas.shape[0]]]
            weights = scaled_weights(3, params["alpha"][camera], params["beta"][camera], params["kappa"][camera])
            states, x_last, P_last = unscented_filter(meas, kinds[camera], Fn, H, Q, R, x0.T, P0.transpose(1, 2, 0),
                                                      weights)
            out[camera] = states[:, :2].transpose(2, 0, 1)
            x_end[camera], P_end[camera] = x_last[:2].T, P_last[:2, :2].transpose(2, 0, 1)
            c_end, P_c_end = x_last[2], P_last[2].T
            waiting = kinds[camera, -1] == WAIT  # not started: NaN state (the next call starts it)
            x_end[np.flatnonzero(camera)[waiting]], P_end[np.flatnonzero(camera)[waiting]] = np.nan, np.nan
            c_end[waiting], P_c_end[waiting] = np.nan, np.nan
        return out, AxisCarry(x=x_end, P=P_end, c=c_end, P_c=P_c_end)


def scaled_weights(n: int, alpha: np.ndarray, beta: np.ndarray, kappa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per channel (C,): the sigma-point scale n + λ = α²(n + κ) (C,) (computed so, not as n + λ, which cancels
    to 0 for α²(n + κ) ≪ n) and the covariance weights W^c (2n+1, C) ([Raj-UKF] eq. 1): W_0^c = λ/(n + λ) + 1 − α²
    + β, W_i^c = 1/(2(n + λ)). (The mean weights W^m are not needed: for a linear model the weighted mean of the
    symmetric points is the centre itself, module docstring.)"""
    spread = alpha**2 * (n + kappa)
    Wc = np.repeat((0.5 / spread)[None], 2 * n + 1, axis=0)  # W_i = 1 / (2(n + λ))
    Wc[0] = (spread - n) / spread + 1.0 - alpha**2 + beta  # λ/(n + λ) + 1 − α² + β
    return spread, Wc


def matrix_root(A: np.ndarray) -> np.ndarray:
    """A square root L (L Lᵀ = A) of every symmetric matrix in A (n, n, C), channel axis last.

    Lower Cholesky factor (a loop over the n ≤ 3 matrix dimensions, vectorised over channels); channels whose
    matrix is not positive definite (e.g. a singular P0) get the symmetric eigen-square-root instead."""
    n = A.shape[0]
    L = np.zeros_like(A)
    definite = np.ones(A.shape[2], dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):  # a channel that overflows is not definite: eigen root
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


def sigma_deviations(P: np.ndarray, spread: np.ndarray) -> np.ndarray:
    """The sigma points' deviations from their centre, [0, +√((n+λ)P)_i, −√((n+λ)P)_i] ([Raj-UKF] eqs. 1, 6):
    P (n, n, C) → (2n+1, n, C); √ is :func:`matrix_root` and [·]_i its column i."""
    offsets = matrix_root(spread * P).transpose(1, 0, 2)  # row i = column i of the root
    return np.concatenate([np.zeros_like(offsets[:1]), offsets, -offsets], axis=0)


def sigma_covariance(dev: np.ndarray, Wc: np.ndarray) -> np.ndarray:
    """Σ_s W^c_s dev_s dev_sᵀ (n, n, C) of the sigma points' deviations ``dev`` (2n+1, n, C) from their mean (eqs. 4,
    8, 10)."""
    return np.einsum("sc,sic,sjc->ijc", Wc, dev, dev)


def sigma_predict(P: np.ndarray, F: np.ndarray, Q: np.ndarray, weights: tuple[np.ndarray, ...]) -> np.ndarray:
    """Predicted covariance P⁻ (n, n, C) of C channels through the sigma points of P (eqs. 6–8), linear f = F."""
    spread, Wc = weights
    return sigma_covariance(np.einsum("ij,sjc->sic", F, sigma_deviations(P, spread)), Wc) + Q


def sigma_update(P_prior: np.ndarray, H: np.ndarray, R_diag: np.ndarray, observed: np.ndarray,
                 weights: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The gain K (n, p, C) through sigma points re-drawn from P⁻ (eqs. 9–12; zero columns for measurements not
    ``observed`` (p, C)), linear h = H, and the posterior covariance P⁻ − K S Kᵀ, symmetrised."""
    spread, Wc = weights
    chi = sigma_deviations(P_prior, spread)  # re-drawn from (x⁻, P⁻), centred
    dz = np.where(observed[None], np.einsum("ij,sjc->sic", H, chi), 0.0)  # Z − ẑ (eq. 9); missing: K column 0
    S = sigma_covariance(dz, Wc) + R_diag  # eq. 10
    Pxz = np.einsum("sc,sic,sjc->ijc", Wc, chi, dz)  # eq. 10
    if H.shape[0] == 1:
        K = Pxz / S[0, 0]  # K = P_xz S⁻¹ (eq. 12)
    else:
        K = np.linalg.solve(S.transpose(2, 0, 1), Pxz.transpose(2, 1, 0)).transpose(2, 1, 0)  # S symmetric
    P = P_prior - np.einsum("ijc,jkc,lkc->ilc", K, S, K)  # eq. 11
    return K, 0.5 * (P + P.transpose(1, 0, 2))


def sigma_gain_recursion(kinds: np.ndarray, params: np.ndarray, P_start: np.ndarray,
                         axis: StateSpaceModel) -> tuple[np.ndarray, int, np.ndarray]:
    """The two-state UKF's affine coefficients (T, 6, G) = [(I − K H) F row-major, K] of G rows with frame
    ``kinds`` (G, T), parameters [σ_w, σ_v, α, β, κ] (G, 5) and start covariance (2, 2, G), the frame from which
    they stay constant, and the last posterior covariance — the contract of
    :func:`bboxtune.filters.kalman_core.gain_recursion`, with the covariances of :func:`sigma_predict` and
    :func:`sigma_update`. Runs the compiled kernel (:mod:`bboxtune.filters.ukf_kernels`) where
    :func:`bboxtune.filters.jit.enabled`, else (and where a covariance is not positive definite) this numpy reference."""
    if jit.enabled():
        compiled = ukf_kernels.sigma_gain_recursion(kinds, params, P_start, axis.F, axis.B[:, 0])
        if compiled is not None:  # else a covariance without a Cholesky root: the reference's eigen-root
            return compiled
    G, T = kinds.shape
    sigma_w, sigma_v, alpha, beta, kappa = params.T
    F, H, b = axis.F, axis.H, axis.B[:, 0]
    Q = np.outer(b, b)[:, :, None] * sigma_w**2
    R = (sigma_v**2)[None, None]
    weights = scaled_weights(2, alpha, beta, kappa)
    coef = np.empty((T, 6, G))
    settled = np.all(kinds == kinds[:, -1:], axis=1)
    settled_from = np.where(settled, 0, T - np.argmax(kinds[:, ::-1] != kinds[:, -1:], axis=1)).max()
    resets = np.any(kinds <= INIT, axis=0)
    P = P_start.copy()
    for n in range(T):
        k = kinds[:, n]
        K, P_new = sigma_update(sigma_predict(P, F, Q, weights), H, R, (k == UPDATE_Y)[None], weights)
        coef[n, :4] = (F[:, :, None] - K[:, 0, None, :] * F[0, None, :, None]).reshape(4, G)  # (I − K H) F, H = [1, 0]
        coef[n, 4:] = K[:, 0]
        if resets[n]:
            reset = k <= INIT
            P_new[:, :, reset] = P_start[:, :, reset]
            frame = coef[n]
            frame[:, reset] = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0])[:, None]  # x = [y, 0] (INIT)
            frame[4, k == WAIT] = 0.0  # x = 0 (WAIT; output NaN)
        if n % 8 == 7 and n >= settled_from and np.array_equal(P_new, P):  # steady: later frames repeat frame n
            coef[n + 1:] = coef[n]
            return coef, n, P_new
        P = P_new
    return coef, T, P


def unscented_filter(y: np.ndarray, kinds: np.ndarray, F: np.ndarray, H: np.ndarray, Q: np.ndarray, R: np.ndarray,
                     x_start: np.ndarray, P_start: np.ndarray,
                     weights: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched linear UKF over C channels (channel axis last), frame by frame: measurements ``y`` (p, T, C) with
    NaN = missing (row 0 decides the frame ``kinds`` (C, T) of :func:`bboxtune.filters.kalman_core.frame_kinds`), transition
    ``F`` (n, n), observation ``H`` (p, n), ``Q`` (n, n, C), ``R`` (p, C) diagonal measurement variances, start
    state/covariance (n, C)/(n, n, C), ``weights`` from :func:`scaled_weights`. Means are propagated exactly
    (x⁻ = F x, ẑ = H x⁻), covariances by :func:`sigma_predict` and :func:`sigma_update`.
    Returns posterior states (T, n, C) (NaN at WAIT frames) and the posterior state (n, C) and covariance
    (n, n, C) at the last frame (the start values for a channel still waiting there)."""
    p, T, C = y.shape
    x, P = x_start.copy(), P_start.copy()
    out = np.empty((T, x.shape[0], C))
    observed = ~np.isnan(y)
    y0 = np.where(observed, y, 0.0)
    R_diag = R[:, None] * np.eye(p)[:, :, None]
    for n in range(T):
        x, P = F @ x, sigma_predict(P, F, Q, weights)  # eqs. 6–8, x⁻ = F x for a linear f
        obs = observed[:, n].copy()
        kind = kinds[:, n]
        if np.any(kind <= INIT):  # WAIT: keep the start values; INIT: start at [y, 0, …], use only the rest of y
            reset = kind <= INIT
            x[:, reset], P[:, :, reset] = x_start[:, reset], P_start[:, :, reset]
            x[0, kind == INIT] = y0[0, n, kind == INIT]
            obs[0, reset] = False
            obs[:, kind == WAIT] = False
        if obs.any():
            K, P = sigma_update(P, H, R_diag, obs, weights)
            x = x + np.einsum("ijc,jc->ic", K, np.where(obs, y0[:, n] - H @ x, 0.0))  # eq. 11, ẑ = H x⁻
        out[n] = x
    return np.where((kinds.T == WAIT)[:, None], np.nan, out), x, P
