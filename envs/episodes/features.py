"""Observation features: computed from the measured boxes only (never the ground truth or the true ψ/σ).

Boxes are (cx, cy, w, h) in pixels; NaN rows are missing detections and are left out of every statistic.
``scale`` is the median of sqrt(w·h) over the measured frames; variances are divided by scale² so the
features of a small and a large object with the same relative noise match. Differences are taken along
time per coordinate; "pos" pools cx and cy, "size" pools w and h.

| index | name              | definition                                                                 | unit |
|-------|-------------------|----------------------------------------------------------------------------|------|
| 0     | log_scale         | log scale                                                                   | log px |
| 1     | log_tau           | log τ                                                                       | log s |
| 2     | log_var_d1_pos    | log(var(Δ pos) / scale²)                                                    | – |
| 3     | log_var_d2_pos    | log(var(Δ² pos) / scale²)                                                   | – |
| 4     | log_var_d1_size   | log(var(Δ size) / scale²)                                                   | – |
| 5     | log_var_d2_size   | log(var(Δ² size) / scale²)                                                  | – |
| 6–8   | acf1..3_d1_pos    | lag-1..3 autocorrelation of Δ pos                                           | – |
| 9–11  | acf1..3_d2_pos    | lag-1..3 autocorrelation of Δ² pos                                          | – |
| 12    | log_nopt_nominal  | log N_opt(σ_v,nominal, σ_w,nominal, τ)                                       | log frames |
| 13    | log_nopt_est      | log N_opt(σ̂_v, σ̂_w, τ) from :func:`estimate_sigmas`                        | log frames |
| 14    | log_sigma_v_est   | log(σ̂_v / scale)                                                           | – |
| 15    | log_sigma_w_est   | log(σ̂_w τ² / scale)                                                        | – |
| 16    | log_var_resid     | log(var(y − ŷ_rule) / scale²), residual of the fixed-rule filter (pilot)    | – |
| 17    | acf1_resid        | lag-1 autocorrelation of that residual (white noise → ≈ 0, CMN → > 0)      | – |
| 18    | frac_missing      | fraction of frames with a missing measurement                              | – |
| 19    | log_n_frames      | log T                                                                       | log frames |

Degenerate statistics (fewer than 4 valid differences, zero variance) are floored at a variance of
1e-12·scale² (so a log stays finite) and a correlation of 0; the features are always finite.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from bboxtune.filters.horizon import n_opt

FEATURE_NAMES: tuple[str, ...] = (
    "log_scale", "log_tau", "log_var_d1_pos", "log_var_d2_pos", "log_var_d1_size", "log_var_d2_size",
    "acf1_d1_pos", "acf2_d1_pos", "acf3_d1_pos", "acf1_d2_pos", "acf2_d2_pos", "acf3_d2_pos",
    "log_nopt_nominal", "log_nopt_est", "log_sigma_v_est", "log_sigma_w_est",
    "log_var_resid", "acf1_resid", "frac_missing", "log_n_frames",
)
_VAR_FLOOR = 1e-12


def autocovariance(x: np.ndarray, lags: int) -> np.ndarray:
    """Pooled autocovariances c_0..c_lags (..., lags + 1) of the m series of ``x`` (..., m, T) (time last),
    NaN-aware: each series is centred on its own mean, and lag-k products are averaged over the pairs where
    both samples exist (0 where there is no such pair). Leading axes are independent tracks."""
    m, T = x.shape[-2:]
    finite = np.isfinite(x)
    out = np.zeros((*x.shape[:-2], lags + 1))
    if T > 0 and finite.all():  # (an empty series takes the NaN-aware branch: no mean of an empty slice)
        c = x - x.mean(axis=-1, keepdims=True)
        for k in range(min(lags, T - 1) + 1):  # loop over lags (≤ 3), not time
            out[..., k] = np.einsum("...it,...it->...", c[..., k:], c[..., : T - k]) / ((T - k) * m)
        return out
    counts = finite.sum(axis=-1, keepdims=True)
    c = np.where(finite, x - np.where(finite, x, 0.0).sum(axis=-1, keepdims=True) / np.maximum(counts, 1), 0.0)
    for k in range(min(lags, T - 1) + 1):
        pairs = (finite[..., k:] & finite[..., : T - k]).sum(axis=(-2, -1))
        products = np.einsum("...it,...it->...", c[..., k:], c[..., : T - k])
        out[..., k] = np.where(pairs > 0, products / np.maximum(pairs, 1), 0.0)
    return out


def _log_var(x: np.ndarray, scale: np.ndarray) -> np.ndarray:
    return np.log(np.maximum(autocovariance(x, 0)[..., 0], _VAR_FLOOR * scale**2) / scale**2)


def _acf(x: np.ndarray, lags: int) -> np.ndarray:
    c = autocovariance(x, lags)
    positive = c[..., :1] > 0
    return np.where(positive, c[..., 1:] / np.where(positive, c[..., :1], 1.0), 0.0)


def _time_last(y: np.ndarray) -> np.ndarray:
    """Boxes (..., T, m) as contiguous series (..., m, T): every statistic here reduces over time."""
    return np.ascontiguousarray(np.swapaxes(y, -1, -2))


def box_scale(y: np.ndarray) -> float | np.ndarray:
    """Median sqrt(w·h) of the measured boxes (px) of ``y`` (T, 4) → float, or (B, T, 4) → (B,); 1.0 when
    no box has a positive area."""
    return _scale(y[..., 2] * y[..., 3])


def _scale(area: np.ndarray) -> float | np.ndarray:
    ok = np.isfinite(area) & (area > 0)
    if ok.all():
        n = area.shape[-1]  # the median by one partial sort (np.median's result, without its overhead)
        middle = np.partition(area, [(n - 1) // 2, n // 2], axis=-1)
        scale = np.sqrt(0.5 * (middle[..., (n - 1) // 2] + middle[..., n // 2]))
    else:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: handled below
            scale = np.sqrt(np.nanmedian(np.where(ok, area, np.nan), axis=-1))
        scale = np.where(ok.any(axis=-1), scale, 1.0)
    return float(scale) if scale.ndim == 0 else scale


def estimate_sigmas(y: np.ndarray, tau: float | np.ndarray) -> tuple[float, float] | tuple[np.ndarray, np.ndarray]:
    """Moment estimates (σ̂_v, σ̂_w) from strided second differences of the positions (cx, cy) of ``y``
    (T, m) → floats, or (B, T, m) with ``tau`` scalar or (B,) → arrays (B,).

    For the white-acceleration CV model with white measurement noise, Δ²y_n = y_n − 2y_{n−1} + y_{n−2} has
    variance c0 = τ⁴σ_w²/2 + 6σ_v² and lag-1 autocovariance c1 = τ⁴σ_w²/4 − 4σ_v², hence
    σ_v² = (c0 − 2 c1) / 14. The stride-k difference y_{n+k} − 2y_n + y_{n−k} has variance
    ≈ (2/3) k³ τ⁴ σ_w² + 6σ_v², so σ_w² is the least-squares slope (relative errors) over the strides
    k = 2, 4, …, 32 shorter than T/8. Coloured noise biases both (that is the point of tuning beyond the
    rule). Each variance is floored at 1e-12·scale² so the result is positive.
    """
    sigma_v, sigma_w = _estimate_sigmas(_time_last(y), tau)
    return (float(sigma_v), float(sigma_w)) if y.ndim == 2 else (sigma_v, sigma_w)


def _estimate_sigmas(y: np.ndarray, tau: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`estimate_sigmas` of series ``y`` (..., m, T) (time last)."""
    T = y.shape[-1]
    scale = _scale(y[..., 2, :] * y[..., 3, :]) if y.shape[-2] == 4 else np.ones(y.shape[:-2])
    tau = np.asarray(tau, dtype=float)
    pos = y[..., :2, :]
    c = autocovariance(np.diff(pos, n=2, axis=-1), 1)
    c0, c1 = c[..., 0], c[..., 1]
    floor = _VAR_FLOOR * np.asarray(scale) ** 2
    var_v = np.maximum((c0 - 2.0 * c1) / 14.0, floor)
    num = den = np.zeros_like(var_v)
    for k in (2, 4, 8, 16, 32):  # strides, not time
        if 8 * k >= T:
            break
        v_k = autocovariance(pos[..., 2 * k:] - 2.0 * pos[..., k:-k] + pos[..., : -2 * k], 0)[..., 0]
        g_k = (2.0 / 3.0) * k**3 * tau**4
        used = v_k > 0
        v_safe = np.where(used, v_k, 1.0)
        num = num + np.where(used, (v_k - 6.0 * var_v) * g_k / v_safe**2, 0.0)
        den = den + np.where(used, g_k**2 / v_safe**2, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(den > 0, num / np.where(den > 0, den, 1.0), 2.0 * (c0 - 6.0 * var_v) / tau**4)
    var_w = np.maximum(slope, floor / tau**4)
    return np.sqrt(var_v), np.sqrt(var_w)


def measurement_features(y: np.ndarray, tau: float | Sequence[float] | np.ndarray,
                         nominal_sigma_v: float | Sequence[float] | np.ndarray,
                         nominal_sigma_w: float | Sequence[float] | np.ndarray, rule_positions: np.ndarray) -> np.ndarray:
    """The observation vector (len(FEATURE_NAMES),) float32 of one track, or (B, len(FEATURE_NAMES)) of B
    tracks of equal length at once.

    ``y``: measured boxes (T, 4) or (B, T, 4) cx, cy, w, h (NaN = missing); ``rule_positions``: the
    fixed-rule filter's position estimates, same shape, on the same measurements (the pilot filter);
    ``tau`` and the nominal σ: scalars or (B,)."""
    batched = y.ndim == 3
    Y = _time_last(y if batched else y[None])  # (B, 4, T)
    resid = Y - _time_last(rule_positions if batched else rule_positions[None])
    B, _, T = Y.shape
    tau = np.broadcast_to(np.asarray(tau, dtype=float), (B,))
    scale = np.broadcast_to(_scale(Y[:, 2] * Y[:, 3]), (B,))
    pos, size = Y[:, :2], Y[:, 2:]
    d1p, d2p = np.diff(pos, axis=-1), np.diff(pos, n=2, axis=-1)
    sv, sw = _estimate_sigmas(Y, tau)
    columns = [
        np.log(scale), np.log(tau),
        _log_var(d1p, scale), _log_var(d2p, scale),
        _log_var(np.diff(size, axis=-1), scale), _log_var(np.diff(size, n=2, axis=-1), scale),
        *_acf(d1p, 3).T, *_acf(d2p, 3).T,
        np.log(n_opt(np.broadcast_to(nominal_sigma_v, (B,)), np.broadcast_to(nominal_sigma_w, (B,)), tau)),
        np.log(n_opt(sv, sw, tau)),
        np.log(sv / scale), np.log(sw * tau**2 / scale),
        _log_var(resid, scale), _acf(resid, 1)[:, 0],
        np.mean(~np.isfinite(Y).all(axis=1), axis=-1), np.full(B, np.log(T)),
    ]
    features = np.stack(columns, axis=-1).astype(np.float32)
    return features if batched else features[0]


WINDOW_FEATURE_NAMES: tuple[str, ...] = ("log_var_resid_window", "acf1_resid_window", "log_var_resid_vs_rule",
                                         "frac_missing_window")


def window_features(y: np.ndarray, estimates: np.ndarray, rule_positions: np.ndarray) -> np.ndarray:
    """What the filter just did, for a sequential tuner (len(WINDOW_FEATURE_NAMES),) float32, from one window's
    measured boxes ``y`` (W, 4) (NaN = missing), the filter's position estimates there and the fixed rule's:

    | index | name                  | definition                                                        | unit |
    |-------|-----------------------|-------------------------------------------------------------------|------|
    | 0     | log_var_resid_window  | log(var(y − ŷ) / scale²): the filter's residuals in the window    | – |
    | 1     | acf1_resid_window     | their lag-1 autocorrelation (coloured noise or lag → > 0)         | – |
    | 2     | log_var_resid_vs_rule | log var(y − ŷ) − log var(y − ŷ_rule): smoother (< 0) or rougher   | – |
    | 3     | frac_missing_window   | fraction of the window's frames without a measurement             | – |

    ``scale`` as in :func:`measurement_features` (median sqrt(w·h) of the window's boxes); floored the same way."""
    Y = _time_last(y[None])
    scale = np.atleast_1d(_scale(Y[:, 2] * Y[:, 3]))
    resid, rule_resid = Y - _time_last(estimates[None]), Y - _time_last(rule_positions[None])
    log_var = _log_var(resid, scale)
    columns = [log_var, _acf(resid, 1)[:, 0], log_var - _log_var(rule_resid, scale),
               np.mean(~np.isfinite(Y).all(axis=1), axis=-1)]
    return np.stack(columns, axis=-1).astype(np.float32)[0]
