"""``render_mode="rgb_array"``: truth (green), measurement (red) and estimate (blue) drawn with OpenCV."""

from __future__ import annotations

import cv2
import numpy as np

_GREEN, _RED, _BLUE = (40, 170, 40), (220, 40, 40), (40, 80, 230)


def draw_episode(truth: np.ndarray, y: np.ndarray, estimate: np.ndarray | None, size: int = 480,
                 frame: int | None = None) -> np.ndarray:
    """An RGB image (size, size, 3) uint8: the centre trajectories of the truth, the measurements and the
    estimate up to ``frame`` (default: the last) with the boxes of that frame, scaled to fit the canvas.
    Boxes are (T, 4) cx, cy, w, h; NaN rows are skipped."""
    frame = len(y) - 1 if frame is None else frame
    tracks = [(truth, _GREEN), (y, _RED)] + ([(estimate, _BLUE)] if estimate is not None else [])
    pts = np.concatenate([b[: frame + 1] for b, _ in tracks])
    pts = pts[np.isfinite(pts).all(axis=1)]
    img = np.full((size, size, 3), 255, np.uint8)
    if len(pts) == 0:
        return img
    lo = (pts[:, :2] - pts[:, 2:] / 2).min(axis=0)
    hi = (pts[:, :2] + pts[:, 2:] / 2).max(axis=0)
    margin = 10
    s = (size - 2 * margin) / max(float((hi - lo).max()), 1e-9)

    def to_px(xy: np.ndarray) -> np.ndarray:
        return np.round((xy - lo) * s + margin).astype(np.int32)

    for boxes, colour in tracks:
        seg = boxes[: frame + 1]
        seg = seg[np.isfinite(seg).all(axis=1)]
        if len(seg) >= 2:
            cv2.polylines(img, [to_px(seg[:, :2]).reshape(-1, 1, 2)], False, colour, 1, cv2.LINE_AA)
        box = boxes[frame]
        if np.isfinite(box).all():
            p1, p2 = to_px(box[:2] - box[2:] / 2), to_px(box[:2] + box[2:] / 2)
            cv2.rectangle(img, tuple(int(v) for v in p1), tuple(int(v) for v in p2), colour, 2)
    return img
