"""OFIR: the optimal (MMSE) FIR filter with a horizon-start prior ([PaleRamon-BBox] Alg. 2; notes §1.5).

[PaleRamon-BBox] Alg. 2 runs the KF (Alg. 1) over the horizon ``i = m+1 … n`` from a prior ``x_m ~ (x̄_m, P_m)`` and
outputs x̂_n. The paper takes (x̄_m, P_m) from a running KF, which makes the filter IIR again. To stay a fixed FIR
kernel this back end uses a **data-linear prior**: at the horizon start m (the oldest valid sample of the window)
``x̄_m = [y_m, 0]`` (position = the measurement, velocity 0) with covariance ``P_m = P0``; the window's later
samples ``y_{m+1} … y_n`` update it. Then x̂_n is linear in the window, with batch form (notes §1.5, information
form of ``K_OFIR = Σ_xy Σ_yy⁻¹``) computed by :func:`bboxtune.filters.oufir.window_gls_gain`.

Default ``P0 = diag(σ_v², (σ_v/τ)²)``: the prior position error is the measurement noise of y_m (exact), the prior
velocity std is one measurement-noise std per frame interval (a convention; the true speed is unknown).
Limits (tested): ``P0 = diag(σ_v², ∞)`` turns y_m into an ordinary measurement, giving OUFIR on the whole window;
``P0⁻¹ → 0`` discards y_m, giving OUFIR on the N − 1 samples after it. Windows with NaN start at their oldest valid
sample; start-up windows at frame 0 (Alg. 2, "m = 0 otherwise"); fewer than 2 valid samples: latest valid
measurement, velocity 0 (:mod:`bboxtune.filters.fir_core`).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from bboxtune.filters.fir_core import check_fir_params
from bboxtune.filters.oufir import KalmanWindowFIR, hold_last, kf_step, window_gls_gain
from bboxtune.filters.validation import VARIANCE_MAX, check_prior_scale, numeric


def default_prior(sigma_v: float, tau: float) -> np.ndarray:
    """The default horizon-start prior covariance ``diag(σ_v², (σ_v/τ)²)`` (units², units²/s²)."""
    return np.diag([sigma_v**2, (sigma_v / tau) ** 2])


def ofir_gain(F: np.ndarray, H: np.ndarray, B: np.ndarray, valid: np.ndarray, sigma_w: float, sigma_v: float,
              P0: np.ndarray) -> np.ndarray:
    """OFIR gain (K, L) of one window: prior ``x̄_a = Hᵀ y_a`` with covariance ``P0`` at the oldest valid sample
    a, updated by the valid samples after it (batch form of [PaleRamon-BBox] Alg. 2; notes §1.5)."""
    valid = np.asarray(valid, bool)
    a = int(np.argmax(valid))
    later = valid[a:].copy()
    later[0] = False  # y_a enters through the prior mean only
    W_y, W_x = window_gls_gain(F, H, B, later, sigma_w / sigma_v, P0 / sigma_v**2)
    W = np.zeros((F.shape[0], valid.size))
    W[:, a:] = W_y
    W[:, a] += (W_x @ H.T)[:, 0]  # x̄_a = Hᵀ y_a
    return W


def ofir_iterative(y: np.ndarray, F: np.ndarray, H: np.ndarray, B: np.ndarray, horizon: int, sigma_w: float,
                   sigma_v: float, P0: np.ndarray) -> np.ndarray:
    """[PaleRamon-BBox] Alg. 2 literally, one output at a time, for one channel ``y`` (T,) (NaN = missing) → (T, K).

    At each n: window max(0, n − N + 1) … n; x̂ = [y_a, 0], P = P0 at its oldest valid sample a, then the KF
    (Alg. 1) for i = a+1 … n. Fewer than 2 valid samples in the window: :func:`bboxtune.filters.oufir.hold_last`."""
    Q = sigma_w**2 * B @ B.T
    out = np.empty((y.size, F.shape[0]))
    for n in range(y.size):
        idx = np.flatnonzero(np.isfinite(y[max(0, n - horizon + 1): n + 1])) + max(0, n - horizon + 1)
        if idx.size < 2:
            out[n] = hold_last(y, n)
            continue
        x, P = H[0] * y[idx[0]], np.array(P0, dtype=float)
        for i in range(idx[0] + 1, n + 1):
            x, P = kf_step(x, P, y[i], F, H, Q, sigma_v**2)
        out[n] = x
    return out


PRIOR_LOW = 1e-30  # smallest eigenvalue of the prior covariance in frame units, relative to σ_v²


def check_prior(P0: object, sigma_v: np.ndarray, tau: float) -> np.ndarray | None:
    """``P0``: None or a finite, symmetric, positive definite (2, 2) covariance with entries within
    ±``VARIANCE_MAX``, eigenvalues in frame units (of ``diag(1, τ) P0 diag(1, τ)``) within [:data:`PRIOR_LOW`,
    :data:`bboxtune.filters.validation.PRIOR_MAX`] × every track's σ_v², and a Cholesky factorisation that succeeds
    (ValueError otherwise)."""
    if P0 is None:
        return None
    P = numeric("P0", P0, f"None or a finite symmetric positive definite (2, 2) covariance with |P0| <= {VARIANCE_MAX:g}")
    if P.shape != (2, 2) or not np.all(np.abs(P) <= VARIANCE_MAX) or not np.array_equal(P, P.T):
        raise ValueError(f"P0={P0!r} is out of range: allowed None or a finite symmetric positive definite (2, 2) "
                         f"covariance of one coordinate's [position, velocity] with |P0| <= {VARIANCE_MAX:g}")
    check_prior_scale(P[None], sigma_v, tau, low=PRIOR_LOW)
    S = np.diag([1.0, tau])
    try:  # positive definite in floating point too (a rotated prior with eigenvalues 1e24 apart is not)
        np.linalg.cholesky(S @ P @ S / np.max(sigma_v) ** 2)
    except np.linalg.LinAlgError:
        raise ValueError(f"P0={P0!r} is not numerically positive definite (its Cholesky factorisation in frame "
                         "units fails); allowed: a positive definite covariance") from None
    return P


class OFIR(KalmanWindowFIR):
    """Optimal FIR filter ([PaleRamon-BBox] Alg. 2) with the data-linear horizon-start prior of this module.

    Parameters: ``sigma_w`` (acceleration noise std, units/s²), ``sigma_v`` (measurement noise std, units),
    ``horizon`` N (integer >= 2; None → :func:`bboxtune.filters.horizon.rule_horizon`) — each a scalar or (B,) per track;
    ``P0``: prior covariance (2, 2) of [position, velocity] at the horizon start, the same for every coordinate
    and track (None → :func:`default_prior` from each track's σ_v; in frame units its eigenvalues within
    [1e-30, 1e8] × σ_v², :func:`check_prior`).

    >>> import numpy as np
    >>> from bboxtune import filters
    >>> f = filters.make("ofir", filters.constant_velocity(0.05), sigma_w=50.0, sigma_v=4.0, horizon=20)
    >>> bool(np.allclose(f.run(np.full((30, 1), 7.0))[-1], [7.0, 0.0]))  # a constant track is reproduced
    True
    """

    name = "ofir"
    DEFAULTS: ClassVar[dict[str, Any]] = {"sigma_w": 1.0, "sigma_v": 1.0, "horizon": None, "P0": None}
    PER_TRACK: ClassVar[tuple[str, ...]] = ("horizon", "sigma_w", "sigma_v")
    START_COUNT = 1
    PRIOR_AT_START = True

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        out = check_fir_params(params, self.model)
        out["P0"] = check_prior(params["P0"], out["sigma_v"], self.model.tau)
        return out

    @classmethod
    def params_in_frames(cls, params: dict[str, Any], tau: float | np.ndarray) -> dict[str, Any]:
        """As the base class, and the prior covariance of [p, v] becomes that of [p, v τ] (one P0 for all
        tracks, so ``tau`` must then be a scalar)."""
        out = super().params_in_frames(params, tau)
        if params.get("P0") is not None:
            if np.ndim(tau) != 0:
                raise ValueError(f"tau has shape {np.shape(tau)} but P0 is one matrix for all tracks; allowed: a scalar tau")
            S = np.diag([1.0, tau])
            out["P0"] = S @ params["P0"] @ S
        return out

    def prior(self, sigma_v: float) -> np.ndarray:
        """The horizon-start prior covariance for a channel with measurement noise std ``sigma_v``."""
        return default_prior(sigma_v, self.model.tau) if self.params["P0"] is None else self.params["P0"]

    def window_gain(self, valid: np.ndarray, params: dict[str, float | int]) -> np.ndarray:
        axis = self.model.axis()
        return ofir_gain(axis.F, axis.H, axis.B, valid, params["sigma_w"], params["sigma_v"],
                         self.prior(params["sigma_v"]))

    def scaled_prior(self, sigma_v: np.ndarray) -> np.ndarray:
        """The horizon-start prior covariances (P, 2, 2) in units of σ_v² of channels with ``sigma_v`` (P,)."""
        if self.params["P0"] is None:  # default_prior(σ_v, τ) / σ_v²
            return np.broadcast_to(np.diag([1.0, 1.0 / self.model.tau**2]), (sigma_v.size, 2, 2))
        return self.params["P0"] / sigma_v[:, None, None] ** 2

    def start_state(self, y_first: np.ndarray, y_now: np.ndarray, gap: np.ndarray,
                    params: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The data-linear prior at the first valid sample: [y_a, 0] with covariance P0 (units of σ_v)."""
        return np.stack([y_now, np.zeros_like(y_now)], axis=1), self.scaled_prior(params["sigma_v"])

    def scan_start(self, y: np.ndarray, valid: np.ndarray, channel: np.ndarray, first: np.ndarray,
                   params: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The window's KF starts after its oldest valid sample a, from the prior [y_a, 0] with covariance P0."""
        T = y.shape[-1]
        following = np.minimum.accumulate(np.where(valid, np.arange(T), T)[:, ::-1], axis=1)[:, ::-1]
        a = following[channel, first]  # the windows passed here hold at least 2 valid samples: a < T
        y_a = y[:, channel, a]
        mean = np.stack([y_a, np.zeros_like(y_a)], axis=-1)
        return a + 1, mean, self.scaled_prior(params["sigma_v"])
