"""Classic OpenCV detectors: one box per frame, NaN when nothing is found (the filters treat it as missing).

Every detector is started on the first frame with the initial box (OTB protocol) and then called once per
frame in order; :func:`detect_video` runs one over a whole video. Boxes are xywh, 0-based, continuous
areas (pixel (i, j) covers [i, i + 1) × [j, j + 1)), float64 (4,). Frames are BGR uint8 (H, W, 3) (grey
(H, W) accepted). Row 0 of :func:`detect_video` is the initial box itself, as OTB trackers report it.

| name       | method                                                                                   |
|------------|------------------------------------------------------------------------------------------|
| ``bgsub``  | mean of the last n frames as background ([Raj-UKF] eq. 13), ``|I − B| > T`` (eq. 14), largest blob |
| ``mog2``   | OpenCV's Gaussian-mixture background model (``createBackgroundSubtractorMOG2``), largest blob |
| ``regions``| hue–saturation back-projection of the initial box → binary image; region labelling      |
|            | (``connectedComponentsWithStats``) + contour search (``findContours``) as in [PaleRamon-CMN]     |
| ``template``| normalised cross-correlation ([Raj-UKF] eq. 15, ``TM_CCOEFF_NORMED``), threshold, optional update |
| ``sift``, ``orb`` | keypoints matched to the initial box (ratio test), RANSAC homography → box (or similarity) |

The last four search near the last found box (``search`` × the box's larger side on each side), widening
the window by that margin for every frame missed since (at most ``MAX_WIDENING`` times); once
``redetect_after`` frames in a row found nothing (default ``MAX_WIDENING + 1``), they re-detect: the window is
the whole frame until the object is found again, so a lost detector never stays stuck at a stale position.
The background subtractors look at the whole frame.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import cv2
import numpy as np

from bboxtune.envs.video.detector import NAN_BOX, Detector, blob_boxes, check_range, to_gray
from bboxtune.envs.video.matching import FeatureDetector, TemplateDetector

DETECTORS: tuple[str, ...] = ("bgsub", "mog2", "template", "sift", "orb", "regions")


def _largest(mask: np.ndarray, min_area: float) -> np.ndarray:
    boxes, areas = blob_boxes(mask, min_area)
    return boxes[np.argmax(areas)] if len(areas) else NAN_BOX.copy()


def _clean(mask: np.ndarray, open_size: int, close_size: int) -> np.ndarray:
    """Morphological opening (removes speckle) then closing (fills holes) of a binary uint8 image."""
    if open_size > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((open_size, open_size), np.uint8))
    if close_size > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((close_size, close_size), np.uint8))
    return mask


class MeanBackground(Detector):
    """Mean background subtraction ([Raj-UKF] §III-A): B = mean of the last ``n_frames`` frames (eq. 13,
    kept as a running sum), foreground ``|I − B| > threshold`` (eq. 14) on grey levels, opening/closing,
    largest blob → box. Fails by design under camera motion or global illumination change (the paper's caveats)."""

    name = "bgsub"

    def __init__(self, n_frames: int = 20, threshold: float = 25.0, min_area: float = 20.0, open_size: int = 3,
                 close_size: int = 5) -> None:
        self.n_frames = int(check_range(self.name, "n_frames", n_frames, 1, 10_000))  # n of eq. 13
        self.threshold = check_range(self.name, "threshold", threshold, 0, 255)  # T of eq. 14, grey levels
        self.min_area = check_range(self.name, "min_area", min_area, 1, 1e9)  # px
        self.open_size, self.close_size = int(open_size), int(close_size)  # px, structuring-element sides

    def _start(self, frame: np.ndarray, box: np.ndarray) -> None:
        g = to_gray(frame).astype(np.float32)
        self._frames = [g]
        self._sum = g.copy()

    def _detect(self, frame: np.ndarray) -> np.ndarray:
        g = to_gray(frame).astype(np.float32)
        B = self._sum / len(self._frames)  # eq. 13
        mask = (np.abs(g - B) > self.threshold).astype(np.uint8)  # eq. 14
        box = _largest(_clean(mask, self.open_size, self.close_size), self.min_area)
        self._frames.append(g)
        self._sum += g
        if len(self._frames) > self.n_frames:
            self._sum -= self._frames.pop(0)
        return box


class MOG2Background(Detector):
    """OpenCV's MOG2 background subtractor (no shadow detection), opening/closing, largest blob → box."""

    name = "mog2"

    def __init__(self, history: int = 100, var_threshold: float = 16.0, min_area: float = 20.0, open_size: int = 3,
                 close_size: int = 5) -> None:
        self.history = int(check_range(self.name, "history", history, 1, 100_000))  # frames
        self.var_threshold = check_range(self.name, "var_threshold", var_threshold, 0, 1e4)  # squared Mahalanobis
        self.min_area = check_range(self.name, "min_area", min_area, 1, 1e9)  # px
        self.open_size, self.close_size = int(open_size), int(close_size)

    def _start(self, frame: np.ndarray, box: np.ndarray) -> None:
        self._model = cv2.createBackgroundSubtractorMOG2(self.history, self.var_threshold, detectShadows=False)
        self._model.apply(frame)

    def _detect(self, frame: np.ndarray) -> np.ndarray:
        mask = (self._model.apply(frame) > 0).astype(np.uint8)
        return _largest(_clean(mask, self.open_size, self.close_size), self.min_area)


class RegionDetector(Detector):
    """Segmentation + region labelling + contour search ([PaleRamon-CMN] §2). The object's colours are the
    hue–saturation bins holding at least ``min_mass`` of the saturated pixels (S >= 60) in the central half
    of the initial box; back-projecting that bin set gives the binary image; label 8-connected regions
    (``connectedComponentsWithStats``), keep the largest region whose centroid lies in the search window,
    trace its outer contour (``findContours``) and return the contour's bounding box."""

    name = "regions"

    def __init__(self, min_mass: float = 0.005, bins: tuple[int, int] = (18, 8), min_area: float = 20.0,
                 search: float = 1.0, open_size: int = 3, close_size: int = 7) -> None:
        self.min_mass = check_range(self.name, "min_mass", min_mass, 0, 1)  # fraction of the box's pixels per bin
        self.bins = (int(check_range(self.name, "bins[0]", bins[0], 2, 180)),  # hue bins
                     int(check_range(self.name, "bins[1]", bins[1], 2, 256)))  # saturation bins
        self.min_area = check_range(self.name, "min_area", min_area, 1, 1e9)  # px
        self.search = check_range(self.name, "search", search, 0, 100)  # × box size
        self.open_size, self.close_size = int(open_size), int(close_size)

    def _start(self, frame: np.ndarray, box: np.ndarray) -> None:
        hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV)
        x, y, w, h = np.rint(box + [box[2] / 4, box[3] / 4, -box[2] / 2, -box[3] / 2]).astype(int)
        mask = np.zeros(hsv.shape[:2], np.uint8)
        mask[max(y, 0):y + h, max(x, 0):x + w] = 1  # central half of the box: little background in it
        mask &= (hsv[..., 1] >= 60) & (hsv[..., 2] >= 40)  # hue is meaningless for grey / dark pixels
        hist = cv2.calcHist([hsv], [0, 1], mask, list(self.bins), [0, 180, 0, 256])
        self._colours = np.where(hist >= self.min_mass * max(float(hist.sum()), 1.0), 255.0, 0.0).astype(np.float32)

    def _detect(self, frame: np.ndarray) -> np.ndarray:
        hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV)
        inside = cv2.calcBackProject([hsv], [0, 1], self._colours, [0, 180, 0, 256], 1)
        binary = _clean((inside > 127).astype(np.uint8), self.open_size, self.close_size)
        n, labels, stats, centroids = cv2.connectedComponentsWithStats(binary, connectivity=8)
        x0, y0, x1, y1 = self.window(binary.shape, self.search)
        in_window = (centroids[:, 0] >= x0) & (centroids[:, 0] < x1) & (centroids[:, 1] >= y0) & (centroids[:, 1] < y1)
        ok = np.flatnonzero(in_window & (stats[:, cv2.CC_STAT_AREA] >= self.min_area))
        ok = ok[ok > 0]  # label 0 is the background
        if len(ok) == 0:
            return NAN_BOX.copy()
        region = (labels == ok[np.argmax(stats[ok, cv2.CC_STAT_AREA])]).astype(np.uint8)
        contours, _ = cv2.findContours(region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        return np.array(cv2.boundingRect(max(contours, key=cv2.contourArea)), dtype=float)


def make_detector(name: str, **params: Any) -> Detector:
    """Detector ``name`` (one of :data:`DETECTORS`) with keyword parameters as documented by its class."""
    factories: dict[str, Callable[..., Detector]] = {
        "bgsub": MeanBackground, "mog2": MOG2Background, "regions": RegionDetector, "template": TemplateDetector,
        "sift": lambda **p: FeatureDetector("sift", **p), "orb": lambda **p: FeatureDetector("orb", **p),
    }
    if name not in factories:
        raise ValueError(f"unknown detector {name!r}; allowed: {', '.join(DETECTORS)}")
    try:
        return factories[name](**params)
    except TypeError as err:
        raise ValueError(f"detector {name!r}: {err}") from None


def detect_video(detector: Detector, frames: Iterable[np.ndarray], init_box: np.ndarray,
                 progress: Callable[[Iterable], Iterable] | None = None) -> np.ndarray:
    """Run ``detector`` over ``frames``: (T, 4) xywh, row 0 = ``init_box``, NaN rows = nothing found.

    ``progress`` optionally wraps the frame iterator (e.g. ``tqdm``)."""
    it = iter(progress(frames) if progress is not None else frames)
    first = next(it, None)
    if first is None:
        raise ValueError("frames is empty: a video needs at least one frame")
    detector.start(first, init_box)
    rows = [np.asarray(init_box, dtype=float)]
    rows.extend(detector.detect(frame) for frame in it)
    return np.vstack(rows)
