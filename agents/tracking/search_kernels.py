"""The compiled kernel of the search's candidate predictions (:func:`bboxtune.agents.tracking.search_tune.predicted_boxes`)
for SORT's filter family (fixed variances, SORT's area guard).

:func:`prior_means` runs :class:`bboxtune.filters.bytetrack_kf.BoxKF`'s recursion in the same operation order
(predict, record the prediction, update, initiate at the first detection), one column (a track × candidate pair)
at a time. Its numpy reference is ``predicted_boxes``' batched loop over the filter's own steps, which runs instead
when ``$BBOXTUNE_JIT=0`` (:mod:`bboxtune.filters.jit`); ``tests/agents/tracking/test_search_kernels.py`` checks
the two agree.
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit

AREA = 2  # SORT's area s: its rate is zeroed before a predict that would take s through 0


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
    for j in range(n):
        began = False
        for t in range(T):
            detected = not np.isnan(z[t, 0, j])
            if began:
                for k in range(m):
                    if k == guard:
                        v[k] *= 0.0 if p[k] + v[k] <= 0 else 1.0
                    P00[k] += P01[k]
                    p[k] += v[k]
                    P01[k] += P11[k]
                    P00[k] += P01[k]
                    P00[k] += Q[0, k, j]
                    P11[k] += Q[1, k, j]
                    prior[t, k, j] = p[k]
                if detected:
                    scored[t, j] = True
                    for k in range(m):
                        S = P00[k] + R[k, j]
                        K1, K0 = P01[k] / S, P00[k] / S
                        innovation = z[t, k, j] - p[k]
                        p[k] += K0 * innovation
                        v[k] += K1 * innovation
                        P11[k] -= K1 * P01[k]
                        P01[k] -= K0 * P01[k]
                        P00[k] -= K0 * P00[k]
            elif detected:
                for k in range(m):
                    p[k], v[k], P01[k] = z[t, k, j], 0.0, 0.0
                    P00[k], P11[k] = P_start[0, k, j], P_start[1, k, j]
                began = True
    return prior, scored
