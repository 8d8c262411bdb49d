"""``render_mode="rgb_array"``: truth (green), measurement (red) and estimate (blue) drawn with OpenCV."""

from __future__ import annotations

import cv2
import numpy as np

_GREEN, _RED, _BLUE = (40, 170, 40), (220, 40, 40), (40, 80, 230)
_MARGIN = 10  # px


def _fit(points: np.ndarray, size: int):
    """A map from track coordinates to pixels that fits ``points`` (n, 2) into a size × size panel."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    s = (size - 2 * _MARGIN) / max(float((hi - lo).max()), 1e-9)
    return lambda xy: np.round((xy - lo) * s + _MARGIN).astype(np.int32)


def draw_episode(truth: np.ndarray, y: np.ndarray, estimate: np.ndarray | None, size: int = 480,
                 frame: int | None = None) -> np.ndarray:
    """An RGB image (size, 2·size, 3) uint8 of the track up to ``frame`` (default: the last).

    Left panel: the boxes of that frame, scaled to fit. Right panel: the centre trajectories, scaled to
    their own extent (jitter is usually far smaller than the box). Boxes are (T, 4) cx, cy, w, h; NaN
    rows are skipped."""
    frame = len(y) - 1 if frame is None else frame
    tracks = [(truth, _GREEN), (y, _RED)] + ([(estimate, _BLUE)] if estimate is not None else [])
    boxes_panel = np.full((size, size, 3), 255, np.uint8)
    paths_panel = np.full((size, size, 3), 255, np.uint8)
    current = np.array([b[frame] for b, _ in tracks])
    current = current[np.isfinite(current).all(axis=1)]
    if len(current):
        to_px = _fit(np.concatenate([current[:, :2] - current[:, 2:] / 2, current[:, :2] + current[:, 2:] / 2]), size)
        for box, colour in ((b[frame], c) for b, c in tracks):
            if np.isfinite(box).all():
                p1, p2 = to_px(box[:2] - box[2:] / 2), to_px(box[:2] + box[2:] / 2)
                cv2.rectangle(boxes_panel, tuple(int(v) for v in p1), tuple(int(v) for v in p2), colour, 2)
    segments = [(b[: frame + 1, :2], c) for b, c in tracks[1:] + tracks[:1]]  # truth drawn last, on top
    segments = [(s[np.isfinite(s).all(axis=1)], c) for s, c in segments]
    finite = [s for s, _ in segments if len(s)]
    if finite:
        to_px = _fit(np.concatenate(finite), size)
        for seg, colour in segments:
            if len(seg) >= 2:
                width = 2 if colour == _GREEN else 1
                cv2.polylines(paths_panel, [to_px(seg).reshape(-1, 1, 2)], False, colour, width, cv2.LINE_AA)
    paths_panel[:, 0] = 160  # a grey rule between the panels
    return np.concatenate([boxes_panel, paths_panel], axis=1)
