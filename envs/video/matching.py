"""Appearance-matching detectors: NCC template matching ([Raj-UKF] §III-B) and keypoint matching ([Raj-UKF]
§III-C uses SURF, which is patent-encumbered and absent from OpenCV's free build; SIFT and ORB stand in).

Conventions as in :mod:`bboxtune.envs.video.detectors` (xywh, 0-based, continuous areas; NaN = nothing found).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from bboxtune.envs.video.detector import NAN_BOX, Detector, check_range, to_gray


def _parabola_peak(left: float, centre: float, right: float) -> float:
    """Sub-pixel offset in [-0.5, 0.5] of the maximum of the parabola through three samples."""
    denom = left - 2.0 * centre + right
    return 0.0 if denom >= 0 else float(np.clip(0.5 * (left - right) / denom, -0.5, 0.5))


REDETECT_SCALE_RATIO = 1.1  # ratio between neighbouring scales of the re-detection search
REDETECT_SCALE_STEPS = 3  # re-detection tries the last scale × ratio^k for |k| <= this (× 0.75 … × 1.33)
RECHECK_MARGIN = 0.1  # γ by which a whole-frame peak of the initial template must beat the tracked match
SCALE_HYSTERESIS = 0.01  # γ by which another scale must beat the last one while tracking (resampled templates
# are smoother and score slightly higher on noisy frames, which would otherwise make the box shrink)


@dataclass(frozen=True)
class _Match:
    """Best NCC peak of one search: score γ, sub-pixel top-left (x, y) of the matched patch in frame px,
    the template's scale s (× its initial size) and the patch's integer size (w, h)."""

    score: float
    x: float
    y: float
    scale: float
    size: tuple[int, int]


class TemplateDetector(Detector):
    """Template matching by the correlation coefficient γ ([Raj-UKF] eq. 15; ``cv2.TM_CCOEFF_NORMED``) on grey
    levels; a peak below ``threshold`` is no detection. The peak is refined to sub-pixel by a parabola through
    its neighbours. Scales s are relative to the initial box and bounded by ``scale_range``.

    * Tracking: the current template is matched in the window around the last found box at the last scale s
      and at s / ``scale_step`` and s × ``scale_step`` (``scale_step`` = 1: fixed size; another scale must score
      :data:`SCALE_HYSTERESIS` higher than s). The box is the initial box scaled by s about the matched patch's
      centre (its size the rounded initial size × s).
    * Re-detection after loss: once ``redetect_after`` frames in a row found nothing, the whole frame is
      searched with the current and the initial template at the scales s × :data:`REDETECT_SCALE_RATIO` ^ k,
      |k| <= :data:`REDETECT_SCALE_STEPS` (an object's size changes little while it is lost; much smaller
      templates match clutter too well); a peak of at least ``redetect_threshold`` (stricter than
      ``threshold``: a whole-frame search meets more look-alikes) re-acquires the object.
    * Re-check: every ``recheck_every`` frames (0: never) while tracking, the initial template is also matched
      over the whole frame at the tracked scale and its neighbours; a peak that reaches ``redetect_threshold``
      and beats the initial template's γ at the tracked place by :data:`RECHECK_MARGIN` replaces the tracked
      match, so a lock on a look-alike (after an occlusion) does not last.
    * Update: ``update`` = β; after a detection the template becomes (1 − β)·template + β·matched patch
      (resampled to the initial size; β = 0: fixed template).

    β = 0.05 and threshold 0.6 were chosen on 12 training videos; the scale search, re-detection and re-check
    settings on 40 training videos (``train-00000`` … ``train-00039``; mean success AUC 0.705 → 0.789)."""

    name = "template"

    def __init__(self, threshold: float = 0.6, update: float = 0.05, search: float = 1.0, scale_step: float = 1.05,
                 scale_range: tuple[float, float] = (0.5, 2.0), redetect_after: int = 1,
                 redetect_threshold: float = 0.7, recheck_every: int = 10) -> None:
        self.threshold = check_range(self.name, "threshold", threshold, -1, 1)  # γ
        self.update = check_range(self.name, "update", update, 0, 1)  # β, template learning rate
        self.search = check_range(self.name, "search", search, 0, 100)  # × box size
        self.scale_step = check_range(self.name, "scale_step", scale_step, 1, 2)  # ratio between tried scales
        lo = check_range(self.name, "scale_range[0]", scale_range[0], 0.05, 1)
        self.scale_range = (lo, check_range(self.name, "scale_range[1]", scale_range[1], 1, 20))  # × initial size
        self.redetect_after = int(check_range(self.name, "redetect_after", redetect_after, 1, 1e9))  # frames missed
        self.redetect_threshold = check_range(self.name, "redetect_threshold", redetect_threshold, -1, 1)  # γ, global
        self.recheck_every = int(check_range(self.name, "recheck_every", recheck_every, 0, 1e9))  # frames; 0: never

    def _start(self, frame: np.ndarray, box: np.ndarray) -> None:
        g = to_gray(frame).astype(np.float32)
        x, y = (int(v) for v in np.clip(np.rint(box[:2]), 0, None))
        w, h = int(round(box[2])), int(round(box[3]))
        self._initial = g[y:y + h, x:x + w].copy()
        self._templ = self._initial.copy()
        self._offset = box[:2] - (x, y)  # sub-pixel part of the initial box, kept (scaled) in every detection
        self._scale = 1.0
        self._frame = 0  # frames detected since the start

    def _scales(self) -> np.ndarray:
        """Scales tried in this frame around the last found scale: its neighbours while tracking, a wider band
        when re-detecting; within ``scale_range``."""
        if self.missed >= self.redetect_after:
            k = np.arange(-REDETECT_SCALE_STEPS, REDETECT_SCALE_STEPS + 1)
            return np.unique(np.clip(self._scale * REDETECT_SCALE_RATIO ** k, *self.scale_range))
        return np.unique(np.clip(self._scale * self.scale_step ** np.arange(-1, 2), *self.scale_range))

    def _match(self, g: np.ndarray, templ: np.ndarray, scale: float,
               window: tuple[int, int, int, int]) -> _Match | None:
        """The best peak of ``templ`` resized by ``scale`` in ``window`` (x0, y0, x1, y1) of ``g``; None if
        the resized template does not fit in the frame."""
        h0, w0 = templ.shape
        w, h = max(int(round(scale * w0)), 4), max(int(round(scale * h0)), 4)
        if w > g.shape[1] or h > g.shape[0]:
            return None
        if (w, h) != (w0, h0):
            templ = cv2.resize(templ, (w, h), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
        x0, y0, x1, y1 = window
        x0, y0 = min(max(x0, 0), g.shape[1] - w), min(max(y0, 0), g.shape[0] - h)
        region = g[y0:max(y1, y0 + h), x0:max(x1, x0 + w)]
        gamma = np.nan_to_num(cv2.matchTemplate(region, templ, cv2.TM_CCOEFF_NORMED), nan=-1.0)  # eq. 15
        _, score, _, (px, py) = cv2.minMaxLoc(gamma)
        dx = _parabola_peak(gamma[py, px - 1], score, gamma[py, px + 1]) if 0 < px < gamma.shape[1] - 1 else 0.0
        dy = _parabola_peak(gamma[py - 1, px], score, gamma[py + 1, px]) if 0 < py < gamma.shape[0] - 1 else 0.0
        return _Match(float(score), x0 + px + dx, y0 + py + dy, scale, (w, h))

    def _best(self, g: np.ndarray, templates: tuple[np.ndarray, ...], scales: np.ndarray,
              window: tuple[int, int, int, int]) -> _Match | None:
        """The highest peak of any of ``templates`` at any of ``scales`` in ``window``; while tracking, a scale
        other than the last one must be :data:`SCALE_HYSTERESIS` higher."""
        found = [m for t in templates for s in scales if (m := self._match(g, t, s, window)) is not None]
        hysteresis = SCALE_HYSTERESIS if self.missed < self.redetect_after else 0.0
        return max(found, key=lambda m: m.score - hysteresis * (m.scale != self._scale), default=None)

    def _detect(self, frame: np.ndarray) -> np.ndarray:
        g = to_gray(frame).astype(np.float32)
        self._frame += 1
        redetecting = self.missed >= self.redetect_after
        window = self.window(g.shape, self.search)  # the whole frame when re-detecting
        best = self._best(g, (self._templ, self._initial) if redetecting else (self._templ,), self._scales(), window)
        if best is None or best.score < (self.redetect_threshold if redetecting else self.threshold):
            return NAN_BOX.copy()
        if not redetecting and self.recheck_every and self._frame % self.recheck_every == 0:
            best = self._recheck(g, best)
        self._scale = best.scale
        if self.update > 0:
            self._update(g, best)
        h0, w0 = self._initial.shape
        w, h = best.size
        cx, cy = best.x + w / 2, best.y + h / 2  # centre of the matched patch
        s = best.scale
        return np.array([cx - s * (w0 / 2 - self._offset[0]), cy - s * (h0 / 2 - self._offset[1]), s * w0, s * h0])

    def _recheck(self, g: np.ndarray, m: _Match) -> _Match:
        """The whole frame's peak of the initial template (at the tracked scale and its neighbours) if it reaches
        ``redetect_threshold`` and beats the initial template's γ at the tracked match ``m`` (within 1 px) by
        :data:`RECHECK_MARGIN`; else ``m``."""
        x, y = int(round(m.x)), int(round(m.y))
        w, h = m.size
        here = self._match(g, self._initial, m.scale, (x - 1, y - 1, x + w + 1, y + h + 1))
        scales = m.scale * self.scale_step ** np.arange(-1, 2)
        other = self._best(g, (self._initial,), scales, (0, 0, g.shape[1], g.shape[0]))
        floor = max(self.redetect_threshold, (-1.0 if here is None else here.score) + RECHECK_MARGIN)
        return other if other is not None and other.score > floor else m

    def _update(self, g: np.ndarray, m: _Match) -> None:
        """Blend the matched patch (resampled to the initial size) into the template."""
        x, y = int(round(m.x)), int(round(m.y))
        w, h = m.size
        patch = g[max(y, 0):y + h, max(x, 0):x + w]
        if patch.shape != (h, w):
            return
        h0, w0 = self._initial.shape
        patch = cv2.resize(patch, (w0, h0), interpolation=cv2.INTER_AREA if m.scale > 1 else cv2.INTER_LINEAR)
        self._templ = (1.0 - self.update) * self._templ + self.update * patch


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
            self._features: cv2.Feature2D = cv2.SIFT.create(contrastThreshold=0.02)
            self._matcher = cv2.BFMatcher(cv2.NORM_L2)
        else:
            self._features = cv2.ORB.create(nfeatures=1000, scaleFactor=1.2, nlevels=4, edgeThreshold=9, patchSize=9,
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
