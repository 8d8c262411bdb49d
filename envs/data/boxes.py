"""Bounding-box format conversions.

Two formats, both (..., 4) float arrays in pixels:

* **xywh** (OTB, pysot, got10k): (x, y) is the top-left corner, (w, h) the width and height. Areas are
  continuous (a box covers [x, x + w) × [y, y + h)), so a 1-based integer OTB box keeps its coordinates.
* **cxcywh** (the filters' measured quantities for ``ndim = 4``): centre ``cx = x + w/2``, ``cy = y + h/2``,
  then w, h.

The OTB Matlab toolkit's centre ``x + (w − 1)/2`` differs by a constant half pixel, which cancels in every
centre error between two boxes. NaN propagates (a missing box stays missing).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def _as_boxes(name: str, boxes: ArrayLike) -> np.ndarray:
    arr = np.asarray(boxes, dtype=float)
    if arr.ndim < 1 or arr.shape[-1] != 4:
        raise ValueError(f"{name} has shape {arr.shape}; allowed: (..., 4)")
    return arr


def xywh_to_cxcywh(boxes: ArrayLike) -> np.ndarray:
    """(x, y, w, h) → (cx, cy, w, h).

    >>> xywh_to_cxcywh([10, 20, 4, 6]).tolist()
    [12.0, 23.0, 4.0, 6.0]
    """
    b = _as_boxes("boxes", boxes)
    out = b.copy()
    out[..., :2] += 0.5 * b[..., 2:]
    return out


def cxcywh_to_xywh(boxes: ArrayLike) -> np.ndarray:
    """(cx, cy, w, h) → (x, y, w, h).

    >>> cxcywh_to_xywh([12, 23, 4, 6]).tolist()
    [10.0, 20.0, 4.0, 6.0]
    """
    b = _as_boxes("boxes", boxes)
    out = b.copy()
    out[..., :2] -= 0.5 * b[..., 2:]
    return out
