"""The compiled kernels of the search (:mod:`bboxtune.agents.tracking.search_tune`) for SORT's filter family (fixed
variances, SORT's area guard).

* :func:`prior_means`: the candidate predictions of ``predicted_boxes``;
* :func:`choose_candidates`: the whole choice of ``CausalSearch.retune`` — every track × candidate recursion, the
  capped prediction IoU, the mean over the scored frames and the choice with its margin and ties to the stock
  candidate — returning only the chosen candidate of each track.

Both run :class:`bboxtune.filters.bytetrack_kf.BoxKF`'s recursion in the same operation order (predict, record
the prediction, update, initiate at the first detection), one column (a track × candidate pair) at a time;
:func:`choose_candidates` computes the IoU as :func:`bboxtune.envs.data.metrics.iou` and the sum over the frames
as numpy's (pairwise) sum, so its choice is the numpy reference's bit for bit. The numpy references
(``predicted_boxes``' batched loop over the filter's own steps, ``candidate_scores`` and the choice in numpy) run
instead when ``$BBOXTUNE_JIT=0`` (:mod:`bboxtune.filters.jit`); ``tests/agents/tracking/test_search_kernels.py``
checks they agree.
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit

AREA = 2  # SORT's area s: its rate is zeroed before a predict that would take s through 0
_BLOCK = 8  # numpy's pairwise sum: the accumulators of its unrolled loop
LONGEST = 128  # numpy's pairwise sum: the longest row it sums in one block (choose_candidates' longest history)


@jit.kernel(inline=True)
def _predict(p: np.ndarray, v: np.ndarray, P00: np.ndarray, P01: np.ndarray, P11: np.ndarray, Q: np.ndarray,
             j: int, guard: int) -> None:
    """One predict of a column's state (p, v, P00, P01, P11: (4,) each) with process variance ``Q[:, :, j]``."""
    for k in range(p.shape[0]):
        if k == guard:
            v[k] *= 0.0 if p[k] + v[k] <= 0 else 1.0
        P00[k] += P01[k]
        p[k] += v[k]
        P01[k] += P11[k]
        P00[k] += P01[k]
        P00[k] += Q[0, k, j]
        P11[k] += Q[1, k, j]


@jit.kernel(inline=True)
def _update(p: np.ndarray, v: np.ndarray, P00: np.ndarray, P01: np.ndarray, P11: np.ndarray, R: np.ndarray,
            j: int, z: np.ndarray) -> None:
    """One update of a column's state with the measurement ``z`` (4,) of variance ``R[:, j]``."""
    for k in range(p.shape[0]):
        S = P00[k] + R[k, j]
        K1, K0 = P01[k] / S, P00[k] / S
        innovation = z[k] - p[k]
        p[k] += K0 * innovation
        v[k] += K1 * innovation
        P11[k] -= K1 * P01[k]
        P01[k] -= K0 * P01[k]
        P00[k] -= K0 * P00[k]


@jit.kernel(inline=True)
def _initiate(p: np.ndarray, v: np.ndarray, P00: np.ndarray, P01: np.ndarray, P11: np.ndarray,
              P_start: np.ndarray, j: int, z: np.ndarray) -> None:
    """A column's state at its first detection ``z`` (4,) with the start variance ``P_start[:, :, j]``."""
    for k in range(p.shape[0]):
        p[k], v[k], P01[k] = z[k], 0.0, 0.0
        P00[k], P11[k] = P_start[0, k, j], P_start[1, k, j]


@jit.kernel
def prior_means(z: np.ndarray, P_start: np.ndarray, Q: np.ndarray, R: np.ndarray, guard: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """The predicted means (T, 4, n) of a box Kalman filter with fixed variances — P₀ and Q (2, 4, n) ([coordinate,
    rate]), R (4, n) — on measured coordinates ``z`` (T, 4, n) (NaN columns: no detection), each frame predicted
    from the frames before it (NaN up to a column's first detection), and where a prediction is scored (T, n):
    frames with a detection after the column's first. ``guard`` >= 0: that coordinate's rate is zeroed before a
    predict that would take it through 0 (:data:`AREA` for SORT); -1: none. All float64, C-contiguous."""
    T, m, n = z.shape
    prior = np.full((T, m, n), np.nan)
    scored = np.zeros((T, n), dtype=np.bool_)
    p, v = np.empty(m), np.empty(m)
    P00, P01, P11 = np.empty(m), np.empty(m), np.empty(m)
    measured = np.empty(m)
    for j in range(n):
        began = False
        for t in range(T):
            detected = not np.isnan(z[t, 0, j])
            for k in range(m):
                measured[k] = z[t, k, j]
            if began:
                _predict(p, v, P00, P01, P11, Q, j, guard)
                for k in range(m):
                    prior[t, k, j] = p[k]
                if detected:
                    scored[t, j] = True
                    _update(p, v, P00, P01, P11, R, j, measured)
            elif detected:
                _initiate(p, v, P00, P01, P11, P_start, j, measured)
                began = True
    return prior, scored


@jit.kernel(inline=True)
def _capped_iou(u: float, v: float, s: float, r: float, box: np.ndarray, cap: float) -> float:
    """min(IoU, ``cap``) of SORT's predicted state (u, v, s, r) with the xywh box ``box``, 0 where the predicted
    box is NaN: :func:`bboxtune.envs.data.metrics.iou` of the box ``SortKF._to_boxes`` and ``cxcywh_to_xywh``
    make of the state, operation for operation."""
    w = np.sqrt(s * r)
    h = s / w
    xa, ya = u - 0.5 * w, v - 0.5 * h
    if np.isnan(xa) or np.isnan(ya) or np.isnan(w) or np.isnan(h):
        return 0.0
    wa, ha = max(w, 0.0), max(h, 0.0)
    wb, hb = max(box[2], 0.0), max(box[3], 0.0)
    iw = min(xa + wa, box[0] + wb) - max(xa, box[0])
    ih = min(ya + ha, box[1] + hb) - max(ya, box[1])
    inter = max(iw, 0.0) * max(ih, 0.0)
    union = wa * ha + wb * hb - inter
    overlap = min(inter / union, 1.0) if union > 0 else 0.0
    return min(overlap, cap)


@jit.kernel(inline=True)
def _pairwise_sum(a: np.ndarray) -> float:
    """numpy's sum of a (n,) float64 row (n <= 128: eight accumulators, then the rest in order), bit for bit."""
    n = a.shape[0]
    if n < _BLOCK:
        total = 0.0
        for i in range(n):
            total += a[i]
        return total
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = _BLOCK
    while i < n - n % _BLOCK:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += _BLOCK
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        total += a[i]
        i += 1
    return total


@jit.kernel
def choose_candidates(y: np.ndarray, P_start: np.ndarray, Q: np.ndarray, R: np.ndarray, guard: int, cap: float,
                      margin: float, stock: int, min_scored: int) -> np.ndarray:
    """The chosen candidate (n,) int64 of each of n tracks of SORT's filter family: their detections ``y`` (n, T, 4)
    xywh px (NaN rows: no detection; T <= :data:`LONGEST`), measured as SORT's (u, v, s, r) by the operations of
    ``xywh_to_cxcywh`` and ``SortKF._measure``, candidate c with the fixed variances
    ``P_start[:, :, c]``, ``Q[:, :, c]`` (2, 4, C) and ``R[:, c]`` (4, C). A candidate's score: the mean over the
    scored frames of min(prediction IoU, ``cap``) (-1 without one), less ``margin`` unless c is ``stock``; the
    best score wins, ties and tracks with fewer than ``min_scored`` scored frames go to ``stock``. ``guard``: as
    :func:`prior_means`. All float64, C-contiguous.

    A track's C candidates run in lockstep (they share its detections, so its branches): the inner loops run over
    the candidates, independent columns the compiler vectorizes; each column's operations are :func:`prior_means`'."""
    n, T, m = y.shape
    n_candidates = Q.shape[2]
    z = np.empty((T, m))  # a track's measured coordinates
    choice = np.full(n, stock, dtype=np.int64)
    overlap = np.zeros((n_candidates, T))
    score = np.empty(n_candidates)
    p, v = np.empty((m, n_candidates)), np.empty((m, n_candidates))
    P00, P01, P11 = np.empty((m, n_candidates)), np.empty((m, n_candidates)), np.empty((m, n_candidates))
    for i in range(n):
        began = False
        count = 0
        overlap[:] = 0.0
        for t in range(T):
            w, h = y[i, t, 2], y[i, t, 3]
            z[t, 0], z[t, 1], z[t, 2], z[t, 3] = y[i, t, 0] + 0.5 * w, y[i, t, 1] + 0.5 * h, w * h, w / h
        for t in range(T):
            detected = not np.isnan(z[t, 0])
            if began:
                if 0 <= guard < m:
                    for c in range(n_candidates):
                        v[guard, c] *= 0.0 if p[guard, c] + v[guard, c] <= 0 else 1.0
                for k in range(m):
                    for c in range(n_candidates):
                        P00[k, c] += P01[k, c]
                        p[k, c] += v[k, c]
                        P01[k, c] += P11[k, c]
                        P00[k, c] += P01[k, c]
                        P00[k, c] += Q[0, k, c]
                        P11[k, c] += Q[1, k, c]
                if detected:
                    count += 1
                    for c in range(n_candidates):
                        overlap[c, t] = _capped_iou(p[0, c], p[1, c], p[2, c], p[3, c], y[i, t], cap)
                    for k in range(m):
                        measured = z[t, k]
                        for c in range(n_candidates):
                            S = P00[k, c] + R[k, c]
                            K1, K0 = P01[k, c] / S, P00[k, c] / S
                            innovation = measured - p[k, c]
                            p[k, c] += K0 * innovation
                            v[k, c] += K1 * innovation
                            P11[k, c] -= K1 * P01[k, c]
                            P01[k, c] -= K0 * P01[k, c]
                            P00[k, c] -= K0 * P00[k, c]
            elif detected:
                for k in range(m):
                    for c in range(n_candidates):
                        p[k, c], v[k, c], P01[k, c] = z[t, k], 0.0, 0.0
                        P00[k, c], P11[k, c] = P_start[0, k, c], P_start[1, k, c]
                began = True
        for c in range(n_candidates):
            mean = _pairwise_sum(overlap[c]) / count if count else -1.0
            score[c] = mean if c == stock else mean - margin
        if count < min_scored:
            continue
        best = 0
        for c in range(1, n_candidates):
            if score[c] > score[best]:
                best = c
        if score[stock] < score[best]:
            choice[i] = best
    return choice
