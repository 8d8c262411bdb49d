"""Detection-to-track association of the SORT family, as small pure functions on xywh boxes (px).

* :func:`iou_matrix` — pairwise IoU (the arithmetic of :func:`bboxtune.envs.data.metrics.iou` over all pairs, tested
  equal); a NaN box overlaps nothing (IoU 0). A compiled kernel, pair by pair, where
  :func:`bboxtune.filters.jit.enabled` (bit for bit :func:`iou_matrix_numpy`, its reference).
* :func:`assign` — SORT's assignment: where the pairs with IoU > ``threshold`` are already one-to-one they are the
  matches; otherwise the Hungarian assignment (``scipy.optimize.linear_sum_assignment``) maximising the summed IoU;
  either way pairs with IoU < ``threshold`` are dropped. (The shortcut matters: maximising the sum can trade one
  pair above the threshold for two below it.) ByteTrack's ``match_thresh`` 0.8 on the cost 1 − IoU is
  ``threshold`` 0.2 here.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import linear_sum_assignment

from bboxtune.filters import jit


def iou_matrix(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """(n, m) IoU of every box of ``a`` (n, 4) with every box of ``b`` (m, 4), xywh px; 0 where either is NaN.

    >>> iou_matrix([[0, 0, 2, 2]], [[1, 0, 2, 2], [5, 5, 1, 1]]).round(3).tolist()
    [[0.333, 0.0]]
    """
    first, second = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    for name, boxes in (("a", first), ("b", second)):
        if boxes.ndim != 2 or boxes.shape[1] != 4:
            raise ValueError(f"{name} has shape {boxes.shape}; allowed (n, 4) xywh boxes")
    if len(first) == 0 or len(second) == 0:
        return np.zeros((len(first), len(second)))
    if jit.enabled():
        return _iou_pairs(np.ascontiguousarray(first), np.ascontiguousarray(second))
    return iou_matrix_numpy(first, second)


def iou_matrix_numpy(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """:func:`iou_matrix` of two non-empty float arrays (n, 4), (m, 4) in numpy: :func:`bboxtune.envs.data.metrics.iou`'s
    arithmetic on the (n, m) pairs, without its per-call checks (a tracker calls this every frame)."""
    x, y, w, h = first.T[:, :, None]
    xb, yb, wb, hb = second.T[:, None, :]
    w, h, wb, hb = np.maximum(w, 0.0), np.maximum(h, 0.0), np.maximum(wb, 0.0), np.maximum(hb, 0.0)
    inter = (np.maximum(np.minimum(x + w, xb + wb) - np.maximum(x, xb), 0.0)
             * np.maximum(np.minimum(y + h, yb + hb) - np.maximum(y, yb), 0.0))
    union = w * h + wb * hb - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(union > 0, np.minimum(inter / np.where(union > 0, union, 1.0), 1.0), 0.0)
    return np.where(np.isnan(out), 0.0, out)  # NaN boxes (and only they) give NaN: IoU 0


@jit.kernel(inline=True)
def _maximum(a: float, b: float) -> float:
    """``np.maximum`` of two floats (NaN if either is)."""
    return a if a >= b or np.isnan(a) else b


@jit.kernel(inline=True)
def _minimum(a: float, b: float) -> float:
    """``np.minimum`` of two floats (NaN if either is)."""
    return a if a <= b or np.isnan(a) else b


@jit.kernel
def _iou_pairs(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """:func:`iou_matrix_numpy`'s arithmetic pair by pair."""
    out = np.empty((first.shape[0], second.shape[0]))
    for i in range(first.shape[0]):
        x, y, w, h = first[i, 0], first[i, 1], _maximum(first[i, 2], 0.0), _maximum(first[i, 3], 0.0)
        for j in range(second.shape[0]):
            xb, yb, wb, hb = second[j, 0], second[j, 1], _maximum(second[j, 2], 0.0), _maximum(second[j, 3], 0.0)
            inter = (_maximum(_minimum(x + w, xb + wb) - _maximum(x, xb), 0.0)
                     * _maximum(_minimum(y + h, yb + hb) - _maximum(y, yb), 0.0))
            union = w * h + wb * hb - inter
            iou = _minimum(inter / union, 1.0) if union > 0 else 0.0
            out[i, j] = 0.0 if np.isnan(iou) else iou
    return out


def assign(overlap: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs (k, 2) of rows and columns of ``overlap`` (an IoU matrix) matched as the module docstring says,
    with IoU >= ``threshold`` (0 < threshold <= 1), then the unmatched rows and the unmatched columns (ascending).

    >>> pairs, rows, cols = assign(np.array([[0.9, 0.1], [0.8, 0.2], [0.0, 0.0]]), 0.3)
    >>> pairs.tolist(), rows.tolist(), cols.tolist()
    ([[0, 0]], [1, 2], [1])
    """
    if not (isinstance(threshold, (int, float)) and 0 < threshold <= 1):
        raise ValueError(f"threshold={threshold!r}; allowed 0 < threshold <= 1")
    n, m = overlap.shape
    pairs = np.empty((0, 2), dtype=np.int64)
    if n and m:
        rows, cols = np.nonzero(overlap > threshold)  # SORT takes these pairs where they are one-to-one
        if len(set(rows.tolist())) < len(rows) or len(set(cols.tolist())) < len(cols):
            rows, cols = linear_sum_assignment(overlap, maximize=True)
        keep = overlap[rows, cols] >= threshold
        pairs = np.stack([rows[keep], cols[keep]], axis=1).astype(np.int64)
    free_rows, free_cols = np.ones(n, dtype=bool), np.ones(m, dtype=bool)
    free_rows[pairs[:, 0]], free_cols[pairs[:, 1]] = False, False
    return pairs, np.flatnonzero(free_rows), np.flatnonzero(free_cols)
