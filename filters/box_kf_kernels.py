"""The compiled recursion of the box Kalman filters without a predict hook (:class:`bboxtune.filters.bytetrack_kf.ByteTrackKF`).

:func:`run_boxes` is :meth:`bboxtune.filters.bytetrack_kf.BoxKF._run_boxes` (its numpy reference, vectorised over
tracks with a loop over frames) as one loop over frames, tracks and coordinates: the same closed-form 2-state
predict / update / initiate, in the same order of floating-point operations, so the means come out bit for bit equal
(tests/filters/test_bytetrack_kf.py), the gap output (:mod:`bboxtune.filters.gap_output`) included. A track's state
X[:, c, j] is [p, v, P01, P00, P11] (v per frame).
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit
from bboxtune.filters.validation import VALUE_MAX


@jit.kernel
def _variance(slope: float, offset: float, fixed: bool, h: float) -> float:
    """(slope · h + offset)², or offset² when the noise does not depend on h (the reference's ``HeightVariance.fixed``)."""
    s = offset if fixed else slope * h + offset
    return s * s


@jit.kernel
def run_boxes(z: np.ndarray, detected: np.ndarray, first: np.ndarray, start: np.ndarray, process: np.ndarray,
              measurement: np.ndarray, fixed: np.ndarray, gapped: bool, decay: np.ndarray, X: np.ndarray,
              output: np.ndarray, means: np.ndarray) -> None:
    """The recursion on measured coordinates ``z`` (T, 4, n) (0 where not ``detected`` (T, n)) from state ``X``
    (5, 4, n), updated in place to the state after the last frame; ``first`` (n,): the frame a waiting track starts
    at (-1: none); the noise as (slope, offset) pairs ``start``, ``process`` (2, 2, 4, n) (pair, then coordinate or
    rate) and ``measurement`` (2, 4, n); ``fixed`` (3,): whether start / process / measurement noise ignores the
    height. Writes the means (T, k, 4, n), k = 1 ([p]) or 2 ([p, v]): the filter's, or if ``gapped`` the gap output
    (:func:`bboxtune.filters.gap_output.step`, per-frame factors ``decay`` (4, n)) from ``output`` (2, 4, n) = [p, v],
    updated in place (``decay`` and ``output`` are not read otherwise)."""
    T, M, n = z.shape
    k = means.shape[1]
    for t in range(T):
        for j in range(n):
            h = X[0, 3, j]  # the current mean height (process noise)
            for c in range(M):
                q_p = _variance(process[0, 0, c, j], process[1, 0, c, j], fixed[1], h)
                q_v = _variance(process[0, 1, c, j], process[1, 1, c, j], fixed[1], h)
                P00 = X[3, c, j] + X[2, c, j]
                X[0, c, j] += X[1, c, j]
                X[2, c, j] += X[4, c, j]
                X[3, c, j] = P00 + X[2, c, j] + q_p
                X[4, c, j] += q_v
            h = X[0, 3, j]  # the predicted height (measurement noise)
            gate = 1.0 if detected[t, j] else 0.0
            for c in range(M):
                r = _variance(measurement[0, c, j], measurement[1, c, j], fixed[2], h)
                S = X[3, c, j] + r
                K0 = X[2, c, j] / S * gate
                K1 = X[3, c, j] / S * gate
                innovation = z[t, c, j] - X[0, c, j]
                X[0, c, j] += K1 * innovation
                X[1, c, j] += K0 * innovation
                X[4, c, j] -= K0 * X[2, c, j]
                X[2, c, j] -= K1 * X[2, c, j]
                X[3, c, j] -= K1 * X[3, c, j]
            if first[j] == t:  # initiate: mean [m, 0], P₀ from the detection's height
                h = z[t, 3, j]
                for c in range(M):
                    X[0, c, j] = z[t, c, j]
                    X[1, c, j] = 0.0
                    X[2, c, j] = 0.0
                    X[3, c, j] = _variance(start[0, 0, c, j], start[1, 0, c, j], fixed[0], h)
                    X[4, c, j] = _variance(start[0, 1, c, j], start[1, 1, c, j], fixed[0], h)
            if not gapped:
                for i in range(k):
                    for c in range(M):
                        means[t, i, c, j] = X[i, c, j]
                continue
            for c in range(M):
                if detected[t, j]:
                    output[0, c, j] = X[0, c, j]
                    output[1, c, j] = X[1, c, j]
                else:
                    output[1, c, j] *= decay[c, j]
                    output[0, c, j] += output[1, c, j]
                for i in range(k):
                    means[t, i, c, j] = output[i, c, j]


@jit.kernel
def _one(values: np.ndarray, j: int) -> float:
    """Track j's value of a per-track parameter (n,), or of one (1,) shared by every track."""
    return values[0] if len(values) == 1 else values[j]


@jit.kernel
def bytetrack_positions(Y: np.ndarray, weight_position: np.ndarray, weight_velocity: np.ndarray, aspect: np.ndarray,
                        aspect_rate: np.ndarray, aspect_measurement: np.ndarray, size_min: float, out: np.ndarray) -> bool:
    """:meth:`bboxtune.filters.bytetrack_kf.ByteTrackKF.positions` of boxes ``Y`` (n, T, 4) cx, cy, w, h (NaN rows:
    no detection) from the start, with the parameters σ_p, σ_v, s_a, s_ȧ, s_m, each per track (n,) or one for all
    (1,): ByteTrack's measured coordinates (x, y, a = w / h, h) and noise pairs built as ``ByteTrackKF._measure`` /
    ``_noise`` build them, then :func:`run_boxes` on all tracks at once, then the boxes (a h for w) in ``out`` (n, T, 4).
    Returns False, leaving ``out`` undefined, where a box is not one the filter takes (a row partly NaN, ±inf, an
    entry beyond ``VALUE_MAX`` or w, h below ``size_min``: the caller's checks name it) or where an estimate from a
    track's first detection on is not finite (the caller reports the failure); else True."""
    n, T, M = Y.shape
    z = np.zeros((T, M, n))
    detected = np.zeros((T, n), dtype=np.bool_)
    first = np.full(n, -1, dtype=np.int64)
    start, process = np.zeros((2, 2, M, n)), np.zeros((2, 2, M, n))
    measurement = np.zeros((2, M, n))
    for j in range(n):
        for t in range(T):
            missing = 0
            for c in range(M):
                value = Y[j, t, c]
                if np.isnan(value):
                    missing += 1
                elif not abs(value) <= VALUE_MAX or (c >= 2 and value < size_min):
                    return False
            if missing == M:
                continue
            if missing:
                return False
            detected[t, j] = True
            z[t, 0, j], z[t, 1, j], z[t, 3, j] = Y[j, t, 0], Y[j, t, 1], Y[j, t, 3]
            z[t, 2, j] = Y[j, t, 2] / Y[j, t, 3]
            if first[j] < 0:
                first[j] = t
        for c in range(M):  # the height's coordinates x, y, h (mask 1) and the aspect a (mask 0), as _noise's columns
            on_height, on_aspect = (0.0, 1.0) if c == 2 else (1.0, 0.0)
            w_p, w_v = on_height * _one(weight_position, j), on_height * _one(weight_velocity, j)
            s_a, s_r = on_aspect * _one(aspect, j), on_aspect * _one(aspect_rate, j)
            start[0, 0, c, j], start[0, 1, c, j], start[1, 0, c, j], start[1, 1, c, j] = 2 * w_p, 10 * w_v, s_a, s_r
            process[0, 0, c, j], process[0, 1, c, j], process[1, 0, c, j], process[1, 1, c, j] = w_p, w_v, s_a, s_r
            measurement[0, c, j], measurement[1, c, j] = w_p, on_aspect * _one(aspect_measurement, j)
    fixed = np.array([not start[0].any(), not process[0].any(), not measurement[0].any()])
    X = np.full((5, M, n), np.nan)
    means = np.empty((T, 1, M, n))
    run_boxes(z, detected, first, start, process, measurement, fixed, False, np.ones((M, n)), X, X[:2], means)
    finite = True
    for j in range(n):
        for t in range(T):
            for c in range(M):
                out[j, t, c] = means[t, 0, c, j]
            out[j, t, 2] = means[t, 0, 2, j] * means[t, 0, 3, j]
            if 0 <= first[j] <= t:
                for c in range(M):
                    finite &= np.isfinite(out[j, t, c])
    return finite
