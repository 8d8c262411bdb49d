"""SORT as published (Bewley et al., ICIP 2016: one filterpy Kalman filter per track, written here from the paper's
description and the notes' equations) — the reference the tracker with ``sort_kf`` must reproduce."""

from __future__ import annotations

import numpy as np
from filterpy.kalman import KalmanFilter
from scipy.optimize import linear_sum_assignment

from bboxtune.agents.tracking.association import iou_matrix


def _z(box: np.ndarray) -> np.ndarray:
    x, y, w, h = box
    return np.array([x + w / 2, y + h / 2, w * h, w / h])


class _Track:
    def __init__(self, box: np.ndarray, track_id: int) -> None:
        kf = KalmanFilter(dim_x=7, dim_z=4)
        kf.F = np.eye(7) + np.eye(7, k=4)
        kf.H = np.eye(4, 7)
        kf.R = np.diag([1.0, 1.0, 10.0, 10.0])
        kf.P = np.diag([10.0, 10, 10, 10, 1e4, 1e4, 1e4])
        kf.Q = np.diag([1.0, 1, 1, 1, 0.01, 0.01, 1e-4])
        kf.x[:4, 0] = _z(box)
        self.kf, self.id = kf, track_id
        self.unmatched = self.streak = 0

    def predict(self) -> np.ndarray:
        if self.kf.x[2, 0] + self.kf.x[6, 0] <= 0:
            self.kf.x[6, 0] = 0.0
        self.kf.predict()
        if self.unmatched > 0:
            self.streak = 0
        self.unmatched += 1
        return self.box()

    def update(self, box: np.ndarray) -> None:
        self.unmatched = 0
        self.streak += 1
        self.kf.update(_z(box))

    def box(self) -> np.ndarray:
        u, v, s, r = self.kf.x[:4, 0]
        w = np.sqrt(s * r)
        h = s / w
        return np.array([u - w / 2, v - h / 2, w, h])


def sort_reference(frames: np.ndarray, boxes: np.ndarray, *, max_age: int = 1, min_hits: int = 3,
                   iou_threshold: float = 0.3) -> list[tuple[int, int, np.ndarray]]:
    """(frame, id, box xywh) of every reported track, in SORT's order of reporting."""
    tracks: list[_Track] = []
    out: list[tuple[int, int, np.ndarray]] = []
    next_id = 1
    for t in range(1, int(frames.max()) + 1):
        dets = boxes[frames == t]
        predicted = np.array([trk.predict() for trk in tracks]).reshape(-1, 4)
        overlap = iou_matrix(dets, predicted)
        matches = np.empty((0, 2), dtype=int)
        if overlap.size:
            above = overlap > iou_threshold
            if above.sum(1).max() <= 1 and above.sum(0).max() <= 1:
                matches = np.argwhere(above)
            else:
                matches = np.stack(linear_sum_assignment(-overlap), axis=1)
            matches = matches[overlap[matches[:, 0], matches[:, 1]] >= iou_threshold]
        for d, k in matches:
            tracks[k].update(dets[d])
        for d in sorted(set(range(len(dets))) - set(matches[:, 0].tolist())):
            tracks.append(_Track(dets[d], next_id))
            next_id += 1
        for trk in tracks:
            if trk.unmatched < 1 and (trk.streak >= min_hits or t <= min_hits):
                out.append((t, trk.id, trk.box()))
        tracks = [trk for trk in tracks if trk.unmatched <= max_age]
    return out
