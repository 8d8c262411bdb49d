"""Appearance-matching detectors: NCC template matching (seed 003 §III-B) and keypoint matching (seed 003
§III-C uses SURF, which is patent-encumbered and absent from OpenCV's free build; SIFT and ORB stand in).

Conventions as in :mod:`envs.video.detectors` (xywh, 0-based, continuous areas; NaN = nothing found).
"""

from __future__ import annotations

import cv2
import numpy as np

from envs.video.detectors import NAN_BOX, Detector, check_range, to_gray


def _parabola_peak(left: float, centre: float, right: float) -> float:
    """Sub-pixel offset in [-0.5, 0.5] of the maximum of the parabola through three samples."""
    denom = left - 2.0 * centre + right
    return 0.0 if denom >= 0 else float(np.clip(0.5 * (left - right) / denom, -0.5, 0.5))


class TemplateDetector(Detector):
    """Template matching by the correlation coefficient γ (seed 003 eq. 15; ``cv2.TM_CCOEFF_NORMED``) in a
    window around the last found box; a peak below ``threshold`` is no detection. The peak is refined to
    sub-pixel by a parabola through its neighbours. The box keeps the template's size (no scale search).
    ``update`` = β: after each detection the template becomes (1 − β)·template + β·matched patch (β = 0:
    fixed template; the default 0.05 and threshold 0.6 were chosen on 12 training videos)."""

    name = "template"

    def __init__(self, threshold: float = 0.6, update: float = 0.05, search: float = 1.0) -> None:
        self.threshold = check_range(self.name, "threshold", threshold, -1, 1)  # γ
        self.update = check_range(self.name, "update", update, 0, 1)  # β, template learning rate
        self.search = check_range(self.name, "search", search, 0, 100)  # × box size

    def _start(self, frame: np.ndarray, box: np.ndarray) -> None:
        g = to_gray(frame).astype(np.float32)
        x, y = (int(v) for v in np.clip(np.rint(box[:2]), 0, None))
        w, h = int(round(box[2])), int(round(box[3]))
        self._templ = g[y:y + h, x:x + w].copy()
        self._offset = box[:2] - (x, y)  # sub-pixel part of the initial box, kept in every detection

    def _detect(self, frame: np.ndarray) -> np.ndarray:
        g = to_gray(frame).astype(np.float32)
        h, w = self._templ.shape
        x0, y0, x1, y1 = self.window(g.shape, self.search)
        x0, y0 = min(x0, g.shape[1] - w), min(y0, g.shape[0] - h)
        region = g[y0:max(y1, y0 + h), x0:max(x1, x0 + w)]
        gamma = np.nan_to_num(cv2.matchTemplate(region, self._templ, cv2.TM_CCOEFF_NORMED), nan=-1.0)  # eq. 15
        _, score, _, (px, py) = cv2.minMaxLoc(gamma)
        if score < self.threshold:
            return NAN_BOX.copy()
        dx = _parabola_peak(gamma[py, px - 1], score, gamma[py, px + 1]) if 0 < px < gamma.shape[1] - 1 else 0.0
        dy = _parabola_peak(gamma[py - 1, px], score, gamma[py + 1, px]) if 0 < py < gamma.shape[0] - 1 else 0.0
        if self.update > 0:
            patch = region[py:py + h, px:px + w]
            self._templ = (1.0 - self.update) * self._templ + self.update * patch
        return np.array([x0 + px + dx + self._offset[0], y0 + py + dy + self._offset[1], w, h], dtype=float)


class FeatureDetector(Detector):
    """Keypoints of the initial box matched to keypoints in the search window (k = 2 nearest neighbours,
    Lowe's ratio test), then a RANSAC homography maps the initial box's corners; its bounding box is the
    detection if it has >= ``min_matches`` inliers and an area within [1/4, 4] of the initial box. Otherwise
    a RANSAC similarity (rotation, scale, translation; ``estimateAffinePartial2D``) of the matches is tried
    under the same checks. Fewer than ``min_matches`` good matches: no detection."""

    def __init__(self, kind: str = "sift", ratio: float = 0.75, min_matches: int = 6, ransac_threshold: float = 3.0,
                 search: float = 1.0, pad: int = 8) -> None:
        if kind not in ("sift", "orb"):
            raise ValueError(f"kind={kind!r}; allowed: 'sift', 'orb'")
        self.name = kind
        self.ratio = check_range(kind, "ratio", ratio, 0, 1)  # Lowe's ratio test
        self.min_matches = int(check_range(kind, "min_matches", min_matches, 3, 10_000))
        self.ransac_threshold = check_range(kind, "ransac_threshold", ransac_threshold, 0, 100)  # px
        self.search = check_range(kind, "search", search, 0, 100)  # × box size
        self.pad = int(check_range(kind, "pad", pad, 0, 1000))  # px of context around crops for descriptors
        if kind == "sift":
            self._features = cv2.SIFT_create(contrastThreshold=0.02)
            self._matcher = cv2.BFMatcher(cv2.NORM_L2)
        else:
            self._features = cv2.ORB_create(nfeatures=1000, scaleFactor=1.2, nlevels=4, edgeThreshold=9, patchSize=9,
                                            fastThreshold=8)
            self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING)

    def _keypoints(self, g: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Keypoints (n, 2) in frame px and descriptors of the region [x0, x1) × [y0, y1) of ``g``."""
        cx0, cy0 = max(x0 - self.pad, 0), max(y0 - self.pad, 0)
        crop = g[cy0:y1 + self.pad, cx0:x1 + self.pad]
        mask = np.zeros_like(crop)
        mask[y0 - cy0:y1 - cy0, x0 - cx0:x1 - cx0] = 255
        kps, des = self._features.detectAndCompute(crop, mask)
        pts = np.array([kp.pt for kp in kps], dtype=np.float32).reshape(-1, 2) + (cx0, cy0)
        return pts, des

    def _start(self, frame: np.ndarray, box: np.ndarray) -> None:
        x, y, w, h = box
        self._ref_pts, self._ref_des = self._keypoints(to_gray(frame), int(np.floor(x)), int(np.floor(y)),
                                                       int(np.ceil(x + w)), int(np.ceil(y + h)))
        self._corners = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]], np.float32)
        self._area = w * h

    def _detect(self, frame: np.ndarray) -> np.ndarray:
        if self._ref_des is None or len(self._ref_des) < 2:
            return NAN_BOX.copy()
        g = to_gray(frame)
        pts, des = self._keypoints(g, *self.window(g.shape, self.search))
        if des is None or len(des) < 2:
            return NAN_BOX.copy()
        pairs = self._matcher.knnMatch(self._ref_des, des, k=2)
        good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < self.ratio * p[1].distance]
        if len(good) < self.min_matches:
            return NAN_BOX.copy()
        src = self._ref_pts[[m.queryIdx for m in good]]
        dst = pts[[m.trainIdx for m in good]]
        H, inliers = cv2.findHomography(src, dst, cv2.RANSAC, self.ransac_threshold)
        box = self._box(H, inliers, perspective=True)
        if np.isnan(box[0]):
            A, inliers = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC,
                                                     ransacReprojThreshold=self.ransac_threshold)
            box = self._box(A, inliers, perspective=False)
        return box

    def _box(self, M: np.ndarray | None, inliers: np.ndarray | None, perspective: bool) -> np.ndarray:
        """Bounding box of the mapped initial corners, NaN if the model is missing or implausible."""
        if M is None or inliers is None or int(inliers.sum()) < self.min_matches:
            return NAN_BOX.copy()
        c = self._corners[None]
        mapped = (cv2.perspectiveTransform(c, M) if perspective else cv2.transform(c, M))[0]
        if not np.all(np.isfinite(mapped)) or not cv2.isContourConvex(mapped.astype(np.float32)):
            return NAN_BOX.copy()
        lo, hi = mapped.min(axis=0), mapped.max(axis=0)
        box = np.array([lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]], dtype=float)
        return box if 0.25 <= box[2] * box[3] / self._area <= 4.0 else NAN_BOX.copy()
