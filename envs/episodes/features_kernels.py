"""Compiled kernels of the observation features (:mod:`bboxtune.envs.episodes.features`), batched over tracks.

The numpy references are in :mod:`bboxtune.envs.episodes.features`: :func:`~bboxtune.envs.episodes.features.autocovariance`
of the :func:`~bboxtune.envs.episodes.features.differences`, ``scale_numpy``, ``statistics_numpy`` and ``sigmas_numpy``.
The kernels compute the same statistics in one pass per track, the differences on the fly (the same operations, so
the same values) and the sums in time order (numpy sums pairwise: the results agree to rounding, ≤ 1e-9 relative);
the box scale is the reference's bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from bboxtune.filters import jit

VAR_FLOOR = 1e-12  # variances are floored at VAR_FLOOR · scale² (features module docstring)
STRIDES = (2, 4, 8, 16, 32)  # strides of the σ_w estimate (features.estimate_sigmas), those with 8k < T used
# Columns of measurement_statistics: autocovariances c_0..c_3 of Δ pos and Δ² pos, the variances of Δ size and
# Δ² size, c_0 and c_1 of the residual, the variances of the strided second differences of pos (one per
# stride; 0 where 8k >= T), the box scale and the fraction of frames missing.
D1_POS, D2_POS, D1_SIZE, D2_SIZE, RESID, STRIDED, SCALE, MISSING = 0, 4, 8, 9, 10, 12, 17, 18
N_STATISTICS = 19


@jit.kernel
def _difference(series: np.ndarray, t: int, order: int, stride: int) -> float:
    """Value t of the difference of ``series`` (T,): ``order`` 0 (x_t), 1 (x_{t+1} − x_t), 2 with ``stride`` 1
    (``np.diff(x, n=2)``: (x_{t+2} − x_{t+1}) − (x_{t+1} − x_t)) or 2 with stride k > 1 (x_{t+2k} − 2 x_{t+k} + x_t)."""
    if order == 0:
        return series[t]
    if order == 1:
        return series[t + 1] - series[t]
    if stride == 1:
        return (series[t + 2] - series[t + 1]) - (series[t + 1] - series[t])
    return series[t + 2 * stride] - 2.0 * series[t + stride] + series[t]


@jit.kernel
def _track_autocovariance(x: np.ndarray, first: int, stop: int, order: int, stride: int, out: np.ndarray,
                          d: np.ndarray, ok: np.ndarray) -> None:
    """Pooled NaN-aware autocovariances c_0..c_{len(out) − 1} into ``out`` of the differences of the series
    ``first``..``stop − 1`` of one track ``x`` (m, T): each series centred on the mean of its finite values, lag-k
    products averaged over the pairs where both exist (0 without a pair); ``len(out)`` <= 4. ``d``, ``ok`` (m, T):
    scratch."""
    L = max(x.shape[1] - order * stride, 0)  # length of a differenced series
    n_lags = min(len(out) - 1, L - 1) + 1
    complete = True
    for j in range(stop - first):
        series = x[first + j]
        total, count = 0.0, 0
        for t in range(L):
            d[j, t] = _difference(series, t, order, stride)
            ok[j, t] = math.isfinite(d[j, t])
            if ok[j, t]:
                total += d[j, t]
                count += 1
        complete = complete and count == L
        mean = total / max(count, 1)
        for t in range(L):
            d[j, t] = d[j, t] - mean if ok[j, t] else 0.0
    # the lag-k sums p_k of d_{t+k} d_t (and q_k of the pairs), each in series then time order, side by side in
    # one pass (independent sums: none waits on another's last addition)
    p0 = p1 = p2 = p3 = 0.0
    q0 = q1 = q2 = q3 = 0
    for j in range(stop - first):
        for t in range(L):
            x = d[j, t]
            p0 += x * x
            if n_lags > 1 and t + 1 < L:
                p1 += d[j, t + 1] * x
            if n_lags > 2 and t + 2 < L:
                p2 += d[j, t + 2] * x
            if n_lags > 3 and t + 3 < L:
                p3 += d[j, t + 3] * x
        if not complete:
            for t in range(L):
                q0 += ok[j, t]
                if n_lags > 1 and t + 1 < L:
                    q1 += ok[j, t + 1] and ok[j, t]
                if n_lags > 2 and t + 2 < L:
                    q2 += ok[j, t + 2] and ok[j, t]
                if n_lags > 3 and t + 3 < L:
                    q3 += ok[j, t + 3] and ok[j, t]
    out[:] = 0.0
    for k, (products, pairs) in enumerate(((p0, q0), (p1, q1), (p2, q2), (p3, q3))):
        if k < n_lags:
            if complete:
                pairs = (L - k) * (stop - first)
            out[k] = products / pairs if pairs > 0 else 0.0


@jit.kernel
def autocovariances(x: np.ndarray, first: int, stop: int, order: int, stride: int, lags: int) -> np.ndarray:
    """:func:`_track_autocovariance` (N, lags + 1) of each track of ``x`` (N, m, T); 0 <= ``lags`` <= 3."""
    if not 0 <= lags <= 3:
        raise ValueError("lags: allowed 0 to 3")
    out = np.zeros((x.shape[0], lags + 1))
    d, ok = np.empty((x.shape[1], x.shape[2])), np.empty((x.shape[1], x.shape[2]), dtype=np.bool_)
    for b in range(x.shape[0]):
        _track_autocovariance(x[b], first, stop, order, stride, out[b], d, ok)
    return out


@jit.kernel
def _select(values: np.ndarray, n: int, k: int) -> float:
    """The k-th smallest of ``values[:n]`` (Wirth's quickselect, in place: afterwards ``values[:k]`` hold the k
    smaller ones). Not ``np.partition``: its numba version takes minutes to compile."""
    low, high = 0, n - 1
    while low < high:
        pivot = values[(low + high) // 2]
        i, j = low, high
        while i <= j:
            while values[i] < pivot:
                i += 1
            while values[j] > pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if k <= j:
            high = j
        elif k >= i:
            low = i
        else:
            break
    return values[k]


@jit.kernel
def _track_scale(w: np.ndarray, h: np.ndarray, values: np.ndarray) -> float:
    """sqrt of the median of the finite positive areas w·h (T,) (the mean of the two middle values for an even
    count); 1.0 without one. ``values`` (T,): scratch."""
    n = 0
    for t in range(len(w)):
        area = w[t] * h[t]
        if math.isfinite(area) and area > 0:
            values[n] = area
            n += 1
    if n == 0:
        return 1.0
    high = _select(values, n, n // 2)  # the upper middle value, the smaller ones before it
    low = high
    if n % 2 == 0:  # the lower middle value: the largest before it
        low = values[0]
        for t in range(1, n // 2):
            low = max(low, values[t])
    return math.sqrt(0.5 * (low + high))


@jit.kernel
def median_scale(area: np.ndarray) -> np.ndarray:
    """The box scale (N,) of each row of areas ``area`` (N, T) (:func:`_track_scale`)."""
    out, ones, values = np.empty(len(area)), np.ones(area.shape[1]), np.empty(area.shape[1])
    for b in range(len(area)):
        out[b] = _track_scale(area[b], ones, values)
    return out


# The autocovariances measurement_statistics computes: (series of the residual (1) or the boxes (0), first, stop,
# difference order, stride, lags + 1, first column); one call site in the kernel (short compile time).
_JOBS = np.array([(0, 0, 2, 1, 1, 4, D1_POS), (0, 0, 2, 2, 1, 4, D2_POS), (0, 2, 4, 1, 1, 1, D1_SIZE),
                  (0, 2, 4, 2, 1, 1, D2_SIZE), (1, 0, 4, 0, 1, 2, RESID)]
                 + [(0, 0, 2, 2, k, 1, STRIDED + i) for i, k in enumerate(STRIDES)], dtype=np.int64)


@jit.kernel
def _track_statistics(y: np.ndarray, resid: np.ndarray, out: np.ndarray, d: np.ndarray, ok: np.ndarray,
                      values: np.ndarray) -> None:
    """The statistics (N_STATISTICS,) into ``out`` (zeros) of one track's boxes ``y`` and the fixed rule's residuals
    ``resid`` (4, T), time last. ``d``, ``ok`` (4, T), ``values`` (T,): scratch."""
    m, T = y.shape
    for job in _JOBS:
        source, first, stop, order, stride, n, column = job
        if stride == 1 or 8 * stride < T:  # the σ_w strides with 8k < T
            _track_autocovariance(resid if source else y, first, stop, order, stride, out[column:column + n], d, ok)
    out[SCALE] = _track_scale(y[2], y[3], values)
    missing = 0
    for t in range(T):
        for j in range(m):
            if not math.isfinite(y[j, t]):
                missing += 1
                break
    out[MISSING] = missing / T


@jit.kernel
def measurement_statistics(y: np.ndarray, resid: np.ndarray) -> np.ndarray:
    """The statistics (B, N_STATISTICS) (columns: the module's constants) of the measured boxes ``y`` (B, 4, T)
    and the fixed rule's residuals ``resid`` (B, 4, T), time last."""
    B, m, T = y.shape
    out = np.zeros((B, N_STATISTICS))
    d, ok, values = np.empty((m, T)), np.empty((m, T), dtype=np.bool_), np.empty(T)
    for b in range(B):
        _track_statistics(y[b], resid[b], out[b], d, ok, values)
    return out


@jit.kernel
def sigmas(c0: np.ndarray, c1: np.ndarray, strided: np.ndarray, tau: np.ndarray, scale: np.ndarray, n_frames: int
           ) -> tuple[np.ndarray, np.ndarray]:
    """(σ̂_v, σ̂_w) (B,) each from c_0, c_1 of Δ² pos (B,), the variances ``strided`` (B, len(STRIDES)) of the strided
    second differences, τ and the box scale (B,) (``features.estimate_sigmas``: σ_v² = (c0 − 2 c1) / 14, σ_w² the
    relative least-squares slope over the strides with 8k < T)."""
    B = len(c0)
    sigma_v, sigma_w = np.empty(B), np.empty(B)
    for b in range(B):
        floor = VAR_FLOOR * scale[b] ** 2
        var_v = np.maximum((c0[b] - 2.0 * c1[b]) / 14.0, floor)
        num = den = 0.0
        for i in range(len(STRIDES)):
            k = STRIDES[i]
            if 8 * k >= n_frames:
                break
            g_k = (2.0 / 3.0) * k**3 * tau[b] ** 4
            v_k = strided[b, i]
            if v_k > 0:
                num += (v_k - 6.0 * var_v) * g_k / v_k**2
                den += g_k**2 / v_k**2
        slope = num / den if den > 0 else 2.0 * (c0[b] - 6.0 * var_v) / tau[b] ** 4
        sigma_v[b], sigma_w[b] = math.sqrt(var_v), math.sqrt(np.maximum(slope, floor / tau[b] ** 4))
    return sigma_v, sigma_w


@jit.kernel
def _log_var(var: float, scale: float) -> float:
    """log(var / scale²), the variance floored at VAR_FLOOR · scale²."""
    return math.log(np.maximum(var, VAR_FLOOR * scale**2) / scale**2)


@jit.kernel
def _correlation(c: np.ndarray, k: int) -> float:
    """Lag-k autocorrelation c_k / c_0 (0 unless c_0 > 0)."""
    return c[k] / c[0] if c[0] > 0 else 0.0


@jit.kernel
def observation(stats: np.ndarray, tau: np.ndarray, sigma_v: np.ndarray, sigma_w: np.ndarray, nominal_v: np.ndarray,
                nominal_w: np.ndarray, n_frames: int, sigma_range: tuple[float, float], tau_range: tuple[float, float]
                ) -> tuple[np.ndarray, bool]:
    """The observation vectors (B, 20) (``features.FEATURE_NAMES``) from the statistics (B, N_STATISTICS), τ, the
    estimated σ̂_v, σ̂_w and the nominal σ (B,), and whether every σ and τ lies in its allowed range (``filters.horizon.n_opt``'s
    check: when not, the caller takes the reference, which raises its error)."""
    B = len(stats)
    out = np.empty((B, 20))
    valid = True
    for b in range(B):
        s, t = stats[b], tau[b]
        scale = s[SCALE]
        for sigma in (sigma_v[b], sigma_w[b], nominal_v[b], nominal_w[b]):
            valid = valid and sigma_range[0] <= sigma <= sigma_range[1]
        valid = valid and tau_range[0] <= t <= tau_range[1]
        d1p, d2p = s[D1_POS:D1_POS + 4], s[D2_POS:D2_POS + 4]
        out[b, 0], out[b, 1] = math.log(scale), math.log(t)
        out[b, 2], out[b, 3] = _log_var(d1p[0], scale), _log_var(d2p[0], scale)
        out[b, 4], out[b, 5] = _log_var(s[D1_SIZE], scale), _log_var(s[D2_SIZE], scale)
        for k in range(1, 4):
            out[b, 5 + k], out[b, 8 + k] = _correlation(d1p, k), _correlation(d2p, k)
        out[b, 12] = math.log(math.sqrt(12.0 * nominal_v[b] / (t**2 * nominal_w[b])))  # log N_opt
        out[b, 13] = math.log(math.sqrt(12.0 * sigma_v[b] / (t**2 * sigma_w[b])))
        out[b, 14], out[b, 15] = math.log(sigma_v[b] / scale), math.log(sigma_w[b] * t**2 / scale)
        out[b, 16], out[b, 17] = _log_var(s[RESID], scale), _correlation(s[RESID:RESID + 2], 1)
        out[b, 18], out[b, 19] = s[MISSING], math.log(n_frames)
    return out, valid


@jit.kernel
def track_observations(y: np.ndarray, rule: np.ndarray, tau: np.ndarray, nominal_v: np.ndarray, nominal_w: np.ndarray,
                       sigma_range: tuple[float, float], tau_range: tuple[float, float]) -> tuple[np.ndarray, bool]:
    """:func:`measurement_statistics`, :func:`sigmas` and :func:`observation` in one call (their results bit for bit)
    from the measured boxes ``y`` and the fixed rule's position estimates ``rule`` (B, T, 4), τ and the nominal σ
    (B,): the observations (B, 20) and whether every σ and τ lies in its allowed range. One call instead of three
    and their numpy glue: what a tuner pays for every track it sees, most of all one track at a time."""
    B, T, m = y.shape
    stats = np.zeros((B, N_STATISTICS))
    series, resid, d = np.empty((m, T)), np.empty((m, T)), np.empty((m, T))
    ok, values = np.empty((m, T), dtype=np.bool_), np.empty(T)
    for b in range(B):  # one track at a time, time last: scratch that stays in the cache
        for j in range(m):
            for t in range(T):
                series[j, t] = y[b, t, j]
                resid[j, t] = y[b, t, j] - rule[b, t, j]
        _track_statistics(series, resid, stats[b], d, ok, values)
    c0, c1 = np.ascontiguousarray(stats[:, D2_POS]), np.ascontiguousarray(stats[:, D2_POS + 1])
    strided = np.ascontiguousarray(stats[:, STRIDED:STRIDED + len(STRIDES)])
    sigma_v, sigma_w = sigmas(c0, c1, strided, tau, np.ascontiguousarray(stats[:, SCALE]), T)
    return observation(stats, tau, sigma_v, sigma_w, nominal_v, nominal_w, T, sigma_range, tau_range)


@jit.kernel
def position_msd(y: np.ndarray, lag: int) -> np.ndarray:
    """Mean of (p_{t+lag} − p_t)² over the frame pairs and centre coordinates (cx, cy) of ``y`` (B, T, 4) where the
    difference is finite, per track (B,); NaN with fewer than 4 such pairs. The sums run in time order (numpy's
    reference, ``features.position_msd_numpy``, sums pairwise: equal to rounding)."""
    B, T = y.shape[0], y.shape[1]
    out = np.empty(B)
    for b in range(B):
        total, n = 0.0, 0
        for t in range(T - lag):
            for j in range(2):
                d = y[b, t + lag, j] - y[b, t, j]
                if math.isfinite(d):
                    total += d * d
                    n += 1
        out[b] = total / n if n >= 4 else math.nan
    return out
