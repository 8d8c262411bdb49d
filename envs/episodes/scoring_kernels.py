"""Compiled scoring (:mod:`bboxtune.filters.jit`): the five scores of
:func:`bboxtune.envs.episodes.scoring.score_estimates` in one pass over the frames of many tracks.

Estimates and truths are (cx, cy, w, h) rows of flat (N, 4) arrays; track s is ``lengths[s]`` rows from
``est_starts[s]`` in the estimates and from ``truth_starts[s]`` in the truths (candidates on one episode share
their truth rows; a batch of episodes has one segment each). Per frame the arithmetic is the numpy reference's,
operation for operation, and the sums over frames are numpy's pairwise summation (:func:`pairwise_sum`), so the
scores equal the reference's bit for bit (the tests allow 1e-9 relative: ``tests/envs/test_scoring_kernels.py``).
"""

from __future__ import annotations

import math

import numpy as np

from bboxtune.envs.data import metrics
from bboxtune.filters import jit

N_SCORES = 5  # rows of the kernel's result, in the order of scoring.SCORE_KEYS
THRESHOLDS = np.ascontiguousarray(metrics.SUCCESS_THRESHOLDS, dtype=np.float64)
RADIUS2 = float(metrics.PRECISION_AT) ** 2  # px², the centre-error threshold squared


@jit.kernel
def _frame_iou(cx: float, cy: float, w: float, h: float, gx: float, gy: float, gw: float, gh: float) -> float:
    """IoU of two finite (cx, cy, w, h) boxes as metrics.iou computes it on xywh boxes (x = cx − w/2, widths clipped
    at 0, 0 for an empty union, at most 1)."""
    x, y = cx - 0.5 * w, cy - 0.5 * h
    gx0, gy0 = gx - 0.5 * gw, gy - 0.5 * gh
    wc, hc, gwc, ghc = max(w, 0.0), max(h, 0.0), max(gw, 0.0), max(gh, 0.0)
    iw = max(min(x + wc, gx0 + gwc) - max(x, gx0), 0.0)
    ih = max(min(y + hc, gy0 + ghc) - max(y, gy0), 0.0)
    inter = iw * ih
    union = wc * hc + gwc * ghc - inter
    return min(inter / union, 1.0) if union > 0.0 else 0.0


@jit.kernel
def _frame_within(cx: float, cy: float, w: float, h: float, gx: float, gy: float, gw: float, gh: float,
                  radius2: float) -> bool:
    """Whether the centre error is at most sqrt(radius2), the centres taken as x + w/2 of the xywh boxes."""
    x, y = cx - 0.5 * w, cy - 0.5 * h
    gx0, gy0 = gx - 0.5 * gw, gy - 0.5 * gh
    dx, dy = (x + 0.5 * w) - (gx0 + 0.5 * gw), (y + 0.5 * h) - (gy0 + 0.5 * gh)
    return dx * dx + dy * dy <= radius2


PAIRWISE_BLOCK = 128  # numpy's PW_BLOCKSIZE


@jit.kernel
def _block_sum(a: np.ndarray, first: int, n: int) -> float:
    """numpy's sum of at most 128 values ``a[first:first + n]``: in order below 8, else 8 running partial sums."""
    if n < 8:
        res = 0.0
        for i in range(first, first + n):
            res += a[i]
        return res
    r = a[first:first + 8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += a[first + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for k in range(i, n):
        res += a[first + k]
    return res


@jit.kernel
def pairwise_sum(a: np.ndarray, first: int, n: int) -> float:
    """Sum of ``a[first:first + n]`` in the order of numpy's ``np.add.reduce`` on contiguous float64, bit for bit:
    blocks of up to 128 values (:func:`_block_sum`), above that the sum of two halves (the first a multiple of 8
    long). numpy's recursion runs here on an explicit stack (numba cannot load a recursive kernel from its cache)."""
    ranges = np.empty((3 * 64, 3), dtype=np.int64)  # pending (first, n, halves summed?), depth <= 64
    sums = np.empty(64)  # finished sums not yet added to their sibling
    ranges[0, 0], ranges[0, 1], ranges[0, 2] = first, n, 0
    top, done = 1, 0
    while top > 0:
        top -= 1
        f, m, combine = ranges[top, 0], ranges[top, 1], ranges[top, 2]
        if m <= PAIRWISE_BLOCK:
            sums[done] = _block_sum(a, f, m)
            done += 1
        elif combine:
            done -= 1
            sums[done - 1] += sums[done]
        else:
            half = m // 2
            half -= half % 8
            ranges[top, 2] = 1  # after both halves: add them
            ranges[top + 1, 0], ranges[top + 1, 1], ranges[top + 1, 2] = f + half, m - half, 0
            ranges[top + 2, 0], ranges[top + 2, 1], ranges[top + 2, 2] = f, half, 0  # the first half first
            top += 3
    return sums[0]


@jit.kernel
def score_segments(est: np.ndarray, truth: np.ndarray, est_starts: np.ndarray, truth_starts: np.ndarray,
                   lengths: np.ndarray, thresholds: np.ndarray, radius2: float) -> np.ndarray:
    """Scores (5, S) of S tracks (module docstring): rmse, iou_mean, success_auc, precision20, iou_precision, with
    score_estimates' conventions (a frame without finite truth is left out; a missing estimate scores IoU 0, no
    centre hit, no detection, and is left out of the RMSE; NaN RMSE / IoU precision without a scored frame)."""
    n_tracks, n_thresholds = len(lengths), len(thresholds)
    out = np.empty((N_SCORES, n_tracks))
    longest = lengths.max() if n_tracks else 0
    squared, overlap = np.zeros(longest), np.zeros(longest)  # per frame; 0 where not scored (as the reference)
    for s in range(n_tracks):
        T = lengths[s]
        n_valid, n_scored, n_within, n_below, n_at_or_below = 0, 0, 0, 0, 0
        for t in range(T):
            squared[t], overlap[t] = 0.0, 0.0
            i, j = est_starts[s] + t, truth_starts[s] + t
            gx, gy, gw, gh = truth[j, 0], truth[j, 1], truth[j, 2], truth[j, 3]
            if not (math.isfinite(gx) and math.isfinite(gy) and math.isfinite(gw) and math.isfinite(gh)):
                continue
            n_valid += 1
            cx, cy, w, h = est[i, 0], est[i, 1], est[i, 2], est[i, 3]
            if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(w) and math.isfinite(h)):
                continue  # a failure: IoU 0 counts below no threshold
            n_scored += 1
            squared[t] = (cx - gx) ** 2 + (cy - gy) ** 2 + (w - gw) ** 2 + (h - gh) ** 2
            overlap[t] = _frame_iou(cx, cy, w, h, gx, gy, gw, gh)
            n_within += _frame_within(cx, cy, w, h, gx, gy, gw, gh, radius2)
            # the thresholds below the IoU (success: IoU > t, OTB) and at or below it ([PaleRamon-BBox] TP: IoU >= t)
            for k in range(n_thresholds):
                n_below += thresholds[k] < overlap[t]
                n_at_or_below += thresholds[k] <= overlap[t]
        n = max(n_valid, 1)
        out[0, s] = math.sqrt(pairwise_sum(squared, 0, T) / n_scored) if n_scored > 0 else np.nan
        out[1, s] = pairwise_sum(overlap, 0, T) / n
        out[2, s] = n_below / (n_thresholds * n)
        out[3, s] = n_within / n
        out[4, s] = n_at_or_below / (n_thresholds * n_scored) if n_scored > 0 else np.nan
    return out
