"""The detector interface of the video front end: :class:`Detector` (start on the first frame with the initial
box, then one xywh box per frame, NaN when nothing is found, searching near the last box), and the small image
helpers the detectors share. The detectors themselves live in :mod:`bboxtune.envs.video.detectors` (background
subtraction, the registry) and :mod:`bboxtune.envs.video.matching` (template and keypoint matching)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import cv2
import numpy as np

NAN_BOX = np.full(4, np.nan)
MAX_WIDENING = 3  # a search window grows by its margin per missed frame, at most this many times


def check_range(owner: str, name: str, value: float, lo: float, hi: float) -> float:
    """``value`` as float if lo <= value <= hi (ValueError naming it otherwise)."""
    if not (np.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"{owner}: {name}={value!r} is out of range: allowed [{lo}, {hi}]")
    return float(value)


def to_gray(frame: np.ndarray) -> np.ndarray:
    """Grey uint8 (H, W) of a BGR (H, W, 3) or grey (H, W) uint8 frame."""
    return frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)


def blob_boxes(mask: np.ndarray, min_area: float) -> tuple[np.ndarray, np.ndarray]:
    """Region labelling of a binary uint8 image: xywh boxes (n, 4) and areas (n,) in px of every
    8-connected foreground region of at least ``min_area`` px."""
    _, _, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    keep = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= min_area) + 1  # label 0 is the background
    return stats[keep, :4].astype(float), stats[keep, cv2.CC_STAT_AREA].astype(float)


class Detector(ABC):
    """A stateful per-frame detector: :meth:`start` once, then :meth:`detect` on every later frame."""

    name: str  # set on the class, or per instance (FeatureDetector: its kind, "sift" or "orb")
    redetect_after: int = MAX_WIDENING + 1  # frames missed in a row after which the search window is the whole frame

    def start(self, frame: np.ndarray, box: np.ndarray) -> None:
        """Initialise on the first frame with the initial xywh box (must lie inside the frame, w, h >= 4)."""
        box = np.asarray(box, dtype=float)
        h, w = frame.shape[:2]
        if box.shape != (4,) or not np.all(np.isfinite(box)) or box[2] < 4 or box[3] < 4:
            raise ValueError(f"{self.name}: initial box {box.tolist()} must be finite xywh with w, h >= 4 px")
        if box[0] < -0.5 or box[1] < -0.5 or box[0] + box[2] > w + 0.5 or box[1] + box[3] > h + 0.5:
            raise ValueError(f"{self.name}: initial box {box.tolist()} is outside the {w}x{h} frame")
        self.last = box.copy()  # last box found
        self.missed = 0  # frames missed since then
        self._start(frame, box)

    @abstractmethod
    def _start(self, frame: np.ndarray, box: np.ndarray) -> None: ...

    def params(self) -> dict[str, Any]:
        """The configuration (constructor parameters) as plain values, e.g. for cache keys."""
        state = ("last", "missed")
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(self).items()
                if not k.startswith("_") and k not in state}

    def detect(self, frame: np.ndarray) -> np.ndarray:
        """The object's xywh box (4,) in ``frame``, NaN (4,) when nothing is found."""
        box = self._detect(frame)
        if np.all(np.isfinite(box)):
            self.last, self.missed = box, 0
        else:
            self.missed += 1
        return box

    @abstractmethod
    def _detect(self, frame: np.ndarray) -> np.ndarray: ...

    def window(self, shape: tuple[int, ...], search: float) -> tuple[int, int, int, int]:
        """Integer search region (x0, y0, x1, y1) around the last found box, clipped to the frame; the whole
        frame once ``redetect_after`` frames in a row found nothing (re-detection after loss)."""
        if self.missed >= self.redetect_after:
            return 0, 0, shape[1], shape[0]
        x, y, w, h = self.last
        m = search * max(w, h) * (1 + min(self.missed, MAX_WIDENING))
        x0, y0 = max(int(np.floor(x - m)), 0), max(int(np.floor(y - m)), 0)
        x1, y1 = min(int(np.ceil(x + w + m)), shape[1]), min(int(np.ceil(y + h + m)), shape[0])
        return x0, y0, x1, y1
