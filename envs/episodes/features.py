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

With ``features="msd"`` (``EnvConfig.features``) the observation has one more entry:

| index | name              | definition                                                                 | unit |
|-------|-------------------|----------------------------------------------------------------------------|------|
| 20    | log_msd_pos       | log(MSD_k / scale²): mean of (p_{t+k} − p_t)² over the frame pairs with both | – |
|       |                   | measured and cx, cy; k = min(64, T // 2) (:func:`msd_lag`)                   |      |

A coloured noise's contribution to it is bounded (2σ_v²/(1 − ψ²) at most) while the motion's grows with the lag,
so it tells slow CMN drift from motion where the short-lag statistics above cannot (on the default simulated
scenario it raised the share of the rule → oracle gap PPO closes from 86 % to 91 %, docs/results-sim.md).

Degenerate statistics (fewer than 4 valid differences, zero variance) are floored at a variance of
1e-12·scale² (so a log stays finite) and a correlation of 0; the features are always finite.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from bboxtune.envs.episodes import features_kernels
from bboxtune.filters import jit
from bboxtune.filters.horizon import n_opt
from bboxtune.filters.threads import in_threads
from bboxtune.filters.validation import SIGMA_RANGE, TAU_RANGE

FEATURE_NAMES: tuple[str, ...] = (
    "log_scale", "log_tau", "log_var_d1_pos", "log_var_d2_pos", "log_var_d1_size", "log_var_d2_size",
    "acf1_d1_pos", "acf2_d1_pos", "acf3_d1_pos", "acf1_d2_pos", "acf2_d2_pos", "acf3_d2_pos",
    "log_nopt_nominal", "log_nopt_est", "log_sigma_v_est", "log_sigma_w_est",
    "log_var_resid", "acf1_resid", "frac_missing", "log_n_frames",
)
# The entry the "msd" feature set (``EnvConfig.features``) appends: how far the centre moves over MSD_LAG frames,
# where CMN (bounded) and motion (growing with the lag) separate
MSD_FEATURE = "log_msd_pos"
MSD_LAG = 64  # frames (msd_lag: at most half the track)


def feature_names(features: str = "base") -> tuple[str, ...]:
    """The observation entries of a feature set (``EnvConfig.features``): ``FEATURE_NAMES``, and :data:`MSD_FEATURE`
    last for ``"msd"``."""
    return FEATURE_NAMES + ((MSD_FEATURE,) if features == "msd" else ())


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


def differences(x: np.ndarray, order: int, stride: int = 1) -> np.ndarray:
    """The differences along time of the series ``x`` (..., T): ``order`` 0 (x itself), 1 or 2 (``np.diff``), or
    with ``order`` 2 and ``stride`` k > 1 the strided second difference x_{n+2k} − 2 x_{n+k} + x_n."""
    if order == 0:
        return x
    if stride == 1:
        return np.diff(x, n=order, axis=-1)
    return x[..., 2 * stride:] - 2.0 * x[..., stride:-stride] + x[..., : -2 * stride]


def _autocov(y: np.ndarray, lags: int, order: int = 0, stride: int = 1, series: tuple[int, int] = (0, 4)) -> np.ndarray:
    """:func:`autocovariance` (B, lags + 1) of the :func:`differences` of the series ``series`` = [first, stop) of
    the tracks ``y`` (B, m, T) (time last, contiguous): by the compiled kernel or in numpy."""
    first, stop = series
    if jit.enabled():
        return features_kernels.autocovariances(y, first, stop, order, stride, lags)
    return autocovariance(differences(y[:, first:stop], order, stride), lags)


def _log_var(var: np.ndarray, scale: np.ndarray) -> np.ndarray:
    return np.log(np.maximum(var, features_kernels.VAR_FLOOR * scale**2) / scale**2)


def _acf(c: np.ndarray) -> np.ndarray:
    """Autocorrelations (B, lags) from autocovariances ``c`` (B, lags + 1)."""
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
    if jit.enabled():
        flat = np.ascontiguousarray(area, dtype=float).reshape(-1, area.shape[-1])
        scale = features_kernels.median_scale(flat).reshape(area.shape[:-1])
        return float(scale) if scale.ndim == 0 else scale
    return scale_numpy(area)


def scale_numpy(area: np.ndarray) -> float | np.ndarray:
    """The numpy reference of the box scale: sqrt of the median of the finite positive ``area`` values (..., T)
    (1.0 where there is none) → float or (...)."""
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
    Y = _time_last(y if y.ndim == 3 else y[None])
    if Y.shape[1] != 4:  # positions only: a box of area 1 (scale 1)
        Y = np.concatenate([Y[:, :2], np.ones_like(Y[:, :2])], axis=1)
    stats = _statistics(Y, Y)
    sigma_v, sigma_w = _sigmas(stats, np.broadcast_to(np.asarray(tau, dtype=float), (len(Y),)), Y.shape[-1])
    return (float(sigma_v[0]), float(sigma_w[0])) if y.ndim == 2 else (sigma_v, sigma_w)


def _statistics(y: np.ndarray, resid: np.ndarray) -> np.ndarray:
    """The statistics (B, N_STATISTICS) of the boxes ``y`` (B, 4, T) and the residuals ``resid`` (B, 4, T) (time
    last, contiguous; columns: ``features_kernels``' constants): by the compiled kernel or :func:`statistics_numpy`."""
    if jit.enabled():
        return features_kernels.measurement_statistics(y, np.ascontiguousarray(resid))
    return statistics_numpy(y, resid)


def statistics_numpy(y: np.ndarray, resid: np.ndarray) -> np.ndarray:
    """The numpy reference of ``features_kernels.measurement_statistics``."""
    k = features_kernels
    B, _, T = y.shape
    out = np.zeros((B, k.N_STATISTICS))
    pos, size = y[:, :2], y[:, 2:]
    out[:, k.D1_POS:k.D1_POS + 4] = autocovariance(differences(pos, 1), 3)
    out[:, k.D2_POS:k.D2_POS + 4] = autocovariance(differences(pos, 2), 3)
    out[:, k.D1_SIZE] = autocovariance(differences(size, 1), 0)[:, 0]
    out[:, k.D2_SIZE] = autocovariance(differences(size, 2), 0)[:, 0]
    out[:, k.RESID:k.RESID + 2] = autocovariance(resid, 1)
    for i, stride in enumerate(k.STRIDES):
        if 8 * stride >= T:
            break
        out[:, k.STRIDED + i] = autocovariance(differences(pos, 2, stride), 0)[:, 0]
    out[:, k.SCALE] = scale_numpy(y[:, 2] * y[:, 3])
    out[:, k.MISSING] = np.mean(~np.isfinite(y).all(axis=1), axis=-1)
    return out


def _sigmas(stats: np.ndarray, tau: np.ndarray, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`estimate_sigmas` (B,) each from the tracks' statistics (B, N_STATISTICS) and τ (B,)."""
    k = features_kernels
    args = (stats[:, k.D2_POS], stats[:, k.D2_POS + 1], stats[:, k.STRIDED:k.STRIDED + len(k.STRIDES)], tau,
            stats[:, k.SCALE], n_frames)
    if jit.enabled():
        return features_kernels.sigmas(*(np.ascontiguousarray(a) for a in args[:5]), n_frames)
    return sigmas_numpy(*args)


def sigmas_numpy(c0: np.ndarray, c1: np.ndarray, strided: np.ndarray, tau: np.ndarray, scale: np.ndarray,
                 n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The numpy reference of ``features_kernels.sigmas``."""
    floor = features_kernels.VAR_FLOOR * scale**2
    var_v = np.maximum((c0 - 2.0 * c1) / 14.0, floor)
    num = den = np.zeros_like(var_v)
    for i, k in enumerate(features_kernels.STRIDES):  # strides, not time
        if 8 * k >= n_frames:
            break
        v_k = strided[:, i]
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
                         nominal_sigma_w: float | Sequence[float] | np.ndarray, rule_positions: np.ndarray,
                         msd: bool = False) -> np.ndarray:
    """The observation vector (len(FEATURE_NAMES),) float32 of one track, or (B, len(FEATURE_NAMES)) of B
    tracks of equal length at once; ``msd=True`` appends :data:`MSD_FEATURE` (:func:`msd_feature`), one entry more.

    ``y``: measured boxes (T, 4) or (B, T, 4) cx, cy, w, h (NaN = missing); ``rule_positions``: the
    fixed-rule filter's position estimates, same shape, on the same measurements (the pilot filter);
    ``tau`` and the nominal σ: scalars or (B,)."""
    batched = y.ndim == 3
    B = y.shape[0] if batched else 1
    tau = _per_track(tau, B)
    obs = _base_features(y if batched else y[None], tau, nominal_sigma_v, nominal_sigma_w,
                         rule_positions if batched else rule_positions[None])
    if msd:
        obs = np.concatenate([obs, msd_feature(y if batched else y[None], obs[:, 0])[:, None]], axis=1)
    features = obs.astype(np.float32)
    return features if batched else features[0]


def _base_features(y: np.ndarray, tau: np.ndarray, nominal_sigma_v: object, nominal_sigma_w: object,
                   rule_positions: np.ndarray) -> np.ndarray:
    """The observations (B, 20) float64 of :func:`measurement_features` from boxes and rule estimates (B, T, 4)."""
    B = len(y)
    nominal = [np.asarray(s) for s in (nominal_sigma_v, nominal_sigma_w)]
    if jit.enabled() and all(s.dtype.kind in "iuf" and s.ndim <= 1 for s in nominal):  # one compiled call
        nominal_v, nominal_w = (_per_track(s, B) for s in nominal)
        Y, rule = (np.ascontiguousarray(a, dtype=float) for a in (y, rule_positions))

        def observe(rows: slice) -> tuple[np.ndarray, bool]:  # in a thread of its own on large batches (no GIL)
            return features_kernels.track_observations(Y[rows], rule[rows], tau[rows], nominal_v[rows], nominal_w[rows],
                                                       SIGMA_RANGE, TAU_RANGE)

        parts = in_threads(observe, B, Y.shape[1] * Y.shape[2])
        if all(valid for _, valid in parts):
            return np.concatenate([obs for obs, _ in parts]) if len(parts) > 1 else parts[0][0]
    Y = _time_last(y)  # (B, 4, T)
    stats = _statistics(Y, Y - _time_last(rule_positions))
    sv, sw = _sigmas(stats, tau, Y.shape[-1])
    return _observation(stats, tau, sv, sw, nominal_sigma_v, nominal_sigma_w, Y.shape[-1])


def msd_lag(n_frames: int) -> int:
    """The lag of :data:`MSD_FEATURE` on a track of ``n_frames``: ``MSD_LAG``, or ``n_frames // 2`` (at least 1) on a
    shorter track, so that at least half of its frames start a pair."""
    return max(1, min(MSD_LAG, n_frames // 2))


def msd_feature(y: np.ndarray, log_scale: np.ndarray) -> np.ndarray:
    """:data:`MSD_FEATURE` of B tracks (B,) float64: log(MSD / scale²), floored like the variances (fewer than 4
    pairs or MSD < 1e-12·scale² → log 1e-12), from the boxes ``y`` (B, T, 4) and their ``log_scale`` (B,)
    (the observation's entry 0)."""
    if jit.enabled():
        msd = features_kernels.position_msd(np.ascontiguousarray(y, dtype=float), msd_lag(y.shape[1]))
    else:
        msd = position_msd_numpy(y)
    floor = np.log(features_kernels.VAR_FLOOR)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.log(msd) - 2.0 * log_scale
    return np.where(np.isnan(msd), floor, np.maximum(value, floor))


def position_msd_numpy(y: np.ndarray) -> np.ndarray:
    """The numpy reference of ``features_kernels.position_msd``: the mean of (p_{t+k} − p_t)² over the frame pairs
    (t, t + k) and centre coordinates (cx, cy) of ``y`` (B, T, 4) where both are finite, k = :func:`msd_lag`;
    NaN where fewer than 4 pairs are."""
    k = msd_lag(y.shape[1])
    with np.errstate(invalid="ignore", over="ignore"):  # inf − inf and overflow: not finite, left out
        d = y[:, k:, :2] - y[:, :-k, :2]
    ok = np.isfinite(d)
    n = ok.sum(axis=(1, 2))
    with np.errstate(over="ignore"):
        total = np.where(ok, d, 0.0) ** 2
    return np.where(n >= 4, total.sum(axis=(1, 2)) / np.maximum(n, 1), np.nan)


def _per_track(value: object, B: int) -> np.ndarray:
    """A scalar or (B,) ``value`` as a contiguous float array (B,) (a scalar repeated)."""
    arr = np.asarray(value, dtype=float)
    return np.full(B, arr) if arr.ndim == 0 else np.ascontiguousarray(np.broadcast_to(arr, (B,)))


def _observation(stats: np.ndarray, tau: np.ndarray, sv: np.ndarray, sw: np.ndarray, nominal_sigma_v: object,
                 nominal_sigma_w: object, T: int) -> np.ndarray:
    """The observations (B, 20) float64: by the compiled kernel, or by :func:`observation_numpy` (which also raises
    ``n_opt``'s error for a σ or τ that is not a number or out of range)."""
    B = len(stats)
    nominal = [np.asarray(s) for s in (nominal_sigma_v, nominal_sigma_w)]
    if jit.enabled() and all(s.dtype.kind in "iuf" and s.ndim <= 1 for s in nominal):
        nominal_v, nominal_w = (np.ascontiguousarray(np.broadcast_to(s.astype(float), (B,))) for s in nominal)
        obs, valid = features_kernels.observation(stats, np.ascontiguousarray(tau), sv, sw, nominal_v, nominal_w, T,
                                                  SIGMA_RANGE, TAU_RANGE)
        if valid:
            return obs
    return observation_numpy(stats, tau, sv, sw, nominal_sigma_v, nominal_sigma_w, T)


def observation_numpy(stats: np.ndarray, tau: np.ndarray, sv: np.ndarray, sw: np.ndarray, nominal_sigma_v: object,
                      nominal_sigma_w: object, T: int) -> np.ndarray:
    """The numpy reference of ``features_kernels.observation``."""
    k = features_kernels
    B = len(stats)
    scale = stats[:, k.SCALE]
    nominal = [np.broadcast_to(np.asarray(s), (B,)) for s in (nominal_sigma_v, nominal_sigma_w)]
    log_nopt = np.log(n_opt(np.concatenate([nominal[0], sv]), np.concatenate([nominal[1], sw]), np.concatenate([tau, tau])))
    d1p, d2p, resid = stats[:, k.D1_POS:k.D1_POS + 4], stats[:, k.D2_POS:k.D2_POS + 4], stats[:, k.RESID:k.RESID + 2]
    columns = [
        np.log(scale), np.log(tau),
        _log_var(d1p[:, 0], scale), _log_var(d2p[:, 0], scale),
        _log_var(stats[:, k.D1_SIZE], scale), _log_var(stats[:, k.D2_SIZE], scale),
        *_acf(d1p).T, *_acf(d2p).T,
        log_nopt[:B], log_nopt[B:],
        np.log(sv / scale), np.log(sw * tau**2 / scale),
        _log_var(resid[:, 0], scale), _acf(resid)[:, 0],
        stats[:, k.MISSING], np.full(B, np.log(T)),
    ]
    return np.stack(columns, axis=-1)


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
    c_resid = _autocov(resid, 1)
    log_var = _log_var(c_resid[:, 0], scale)
    columns = [log_var, _acf(c_resid)[:, 0], log_var - _log_var(_autocov(rule_resid, 0)[:, 0], scale),
               np.mean(~np.isfinite(Y).all(axis=1), axis=-1)]
    return np.stack(columns, axis=-1).astype(np.float32)[0]
