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

import numpy as np

from filters.horizon import n_opt

FEATURE_NAMES: tuple[str, ...] = (
    "log_scale", "log_tau", "log_var_d1_pos", "log_var_d2_pos", "log_var_d1_size", "log_var_d2_size",
    "acf1_d1_pos", "acf2_d1_pos", "acf3_d1_pos", "acf1_d2_pos", "acf2_d2_pos", "acf3_d2_pos",
    "log_nopt_nominal", "log_nopt_est", "log_sigma_v_est", "log_sigma_w_est",
    "log_var_resid", "acf1_resid", "frac_missing", "log_n_frames",
)
_VAR_FLOOR = 1e-12


def autocovariance(x: np.ndarray, lags: int) -> np.ndarray:
    """Pooled autocovariances c_0..c_lags of the columns of ``x`` (T, m), NaN-aware: each column is
    centred on its own mean, and lag-k products are averaged over the pairs where both samples exist."""
    finite = np.isfinite(x)
    out = np.zeros(lags + 1)
    if finite.all():
        c = x - x.mean(axis=0)
        for k in range(min(lags, len(c) - 1) + 1):  # loop over lags (≤ 3), not time
            out[k] = np.einsum("ij,ij->", c[k:], c[: len(c) - k]) / ((len(c) - k) * c.shape[1])
        return out
    counts = finite.sum(axis=0)
    c = np.where(finite, x - np.where(finite, x, 0.0).sum(axis=0) / np.maximum(counts, 1), 0.0)
    for k in range(min(lags, len(c) - 1) + 1):
        pairs = (finite[k:] & finite[: len(c) - k]).sum()
        out[k] = np.einsum("ij,ij->", c[k:], c[: len(c) - k]) / pairs if pairs else 0.0
    return out


def _log_var(x: np.ndarray, scale: float) -> float:
    return float(np.log(max(autocovariance(x, 0)[0], _VAR_FLOOR * scale**2) / scale**2))


def _acf(x: np.ndarray, lags: int) -> np.ndarray:
    c = autocovariance(x, lags)
    return c[1:] / c[0] if c[0] > 0 else np.zeros(lags)


def box_scale(y: np.ndarray) -> float:
    """Median sqrt(w·h) of the measured boxes (px); 1.0 when no box has a positive area."""
    area = y[:, 2] * y[:, 3]
    ok = np.isfinite(area) & (area > 0)
    return float(np.sqrt(np.median(area[ok]))) if ok.any() else 1.0


def estimate_sigmas(y: np.ndarray, tau: float) -> tuple[float, float]:
    """Moment estimates (σ̂_v, σ̂_w) from strided second differences of the positions (cx, cy).

    For the white-acceleration CV model with white measurement noise, Δ²y_n = y_n − 2y_{n−1} + y_{n−2} has
    variance c0 = τ⁴σ_w²/2 + 6σ_v² and lag-1 autocovariance c1 = τ⁴σ_w²/4 − 4σ_v², hence
    σ_v² = (c0 − 2 c1) / 14. The stride-k difference y_{n+k} − 2y_n + y_{n−k} has variance
    ≈ (2/3) k³ τ⁴ σ_w² + 6σ_v², so σ_w² is the least-squares slope (relative errors) over the strides
    k = 2, 4, …, 32 shorter than T/8. Coloured noise biases both (that is the point of tuning beyond the
    rule). Each variance is floored at 1e-12·scale² so the result is positive.
    """
    scale = box_scale(y) if y.shape[1] == 4 else 1.0
    pos = y[:, :2]
    c0, c1 = autocovariance(np.diff(pos, n=2, axis=0), 1)
    floor = _VAR_FLOOR * scale**2
    var_v = max((c0 - 2.0 * c1) / 14.0, floor)
    num = den = 0.0
    for k in (2, 4, 8, 16, 32):  # strides, not time
        if 8 * k >= len(pos):
            break
        v_k = autocovariance(pos[2 * k:] - 2.0 * pos[k:-k] + pos[: -2 * k], 0)[0]
        g_k = (2.0 / 3.0) * k**3 * tau**4
        if v_k > 0:
            num += (v_k - 6.0 * var_v) * g_k / v_k**2
            den += g_k**2 / v_k**2
    var_w = max(num / den if den > 0 else 2.0 * (c0 - 6.0 * var_v) / tau**4, floor / tau**4)
    return float(np.sqrt(var_v)), float(np.sqrt(var_w))


def measurement_features(y: np.ndarray, tau: float, nominal_sigma_v: float, nominal_sigma_w: float,
                         rule_positions: np.ndarray) -> np.ndarray:
    """The observation vector (len(FEATURE_NAMES),) float32 of one track.

    ``y``: measured boxes (T, 4) cx, cy, w, h (NaN = missing); ``rule_positions``: the fixed-rule filter's
    position estimates (T, 4) on the same measurements (the pilot filter)."""
    scale = box_scale(y)
    pos, size = y[:, :2], y[:, 2:]
    d1p, d2p = np.diff(pos, axis=0), np.diff(pos, n=2, axis=0)
    sv, sw = estimate_sigmas(y, tau)
    resid = y - rule_positions
    feats = [
        np.log(scale), np.log(tau),
        _log_var(d1p, scale), _log_var(d2p, scale),
        _log_var(np.diff(size, axis=0), scale), _log_var(np.diff(size, n=2, axis=0), scale),
        *_acf(d1p, 3), *_acf(d2p, 3),
        np.log(n_opt(nominal_sigma_v, nominal_sigma_w, tau)), np.log(n_opt(sv, sw, tau)),
        np.log(sv / scale), np.log(sw * tau**2 / scale),
        _log_var(resid, scale), _acf(resid, 1)[0],
        float(np.mean(~np.isfinite(y).all(axis=1))), np.log(len(y)),
    ]
    return np.asarray(feats, dtype=np.float32)
