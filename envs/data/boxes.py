"""Bounding-box format conversions.

Two formats, both (..., 4) float arrays in pixels:

* **xywh** (OTB, pysot, got10k): (x, y) is the top-left corner, (w, h) the width and height. Areas are
  continuous (a box covers [x, x + w) × [y, y + h)), so a 1-based integer OTB box keeps its coordinates.
* **cxcywh** (the filters' measured quantities for ``ndim = 4``): centre ``cx = x + w/2``, ``cy = y + h/2``,
  then w, h.

The OTB Matlab toolkit's centre ``x + (w − 1)/2`` differs by a constant half pixel, which cancels in every
centre error between two boxes. NaN propagates (a missing box stays missing).

Magnitude: every box coordinate the project reads or is handed — x, y, w, h in px — is at most :data:`MAX_COORD`
(1e7 px) in absolute value, far beyond any image (an 8K frame is 7680 px wide) and far below where the filters'
squared errors and covariances lose precision or overflow (boxes near 1e300 did). The readers (OTB box files and
``OTB100.json``, :mod:`bboxtune.envs.data.otb_io`; MOT15 files, :mod:`bboxtune.envs.data.mot_io`) refuse a larger
value naming the file and line, the API (``bboxtune.agents.tune`` / ``smooth``) naming the argument.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

MAX_COORD = 1e7  # px: the largest |x|, |y|, w, h accepted anywhere (module docstring)
COORD_RULE = f"|x|, |y|, w, h <= {MAX_COORD:.0e} px".replace("e+0", "e")  # the bound as error messages state it


def beyond_max_coord(boxes: np.ndarray) -> np.ndarray:
    """Mask over the rows of ``boxes`` (..., 4): any \\|value\\| > :data:`MAX_COORD` (NaN is not beyond).

    >>> beyond_max_coord(np.array([[1e7, -1e7, 5, 5], [0, 0, 1.0000001e7, 1]])).tolist()
    [False, True]
    """
    return (np.abs(boxes) > MAX_COORD).any(axis=-1)


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
