"""Camera-motion estimate from the frames and camera-motion compensation for any back end.

Background motion: corners (``goodFeaturesToTrack``) of frame n−1 tracked into frame n by pyramidal
Lucas–Kanade; a RANSAC similarity separates the background (the majority) from the object and the mean
displacement of its inliers is the apparent background shift ``d_n`` (px, frame n relative to n−1; frame 0
has no predecessor: 0). On the synthetic generator this measures the true shift to about 0.02 px per frame.

Two ways to use it ([Raj-UKF] §IV):

* UKF with the camera-augmented model of eq. 17 (``bboxtune.filters.make("ukf", ..., camera_motion=True)``), fed
  the apparent background velocity at each frame (:func:`background_velocity`, px/s) —
  :func:`run_compensated` with ``backend="ukf"``;
* the camera-velocity input of eq. 18 for any linear back end: with the camera velocity known, adding it as
  a control input to the CV model is the same as filtering in stabilised coordinates
  ``y_n + o_n`` (o_n = −Σ_{k≤n} d_k, the camera offset), then subtracting o_n from the positions and
  adding d_n / τ to the velocities (exactly equal for KF / FIR filters: the known input enters linearly).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import cv2
import numpy as np

from bboxtune import filters
from bboxtune.envs.video.detector import to_gray

_MAX_CORNERS = 300  # corners tracked per frame
_RANSAC_PX = 0.5  # px, inlier threshold of the background similarity
# eq. 17 UKF defaults: a hand-held camera's apparent acceleration (shake of a few px at 1–3 Hz reaches
# ~10³ px/s²) and the error of the measured background velocity (~0.05 px per frame at 30 fps)
UKF_CAMERA = {"sigma_c": 1000.0, "sigma_u": 3.0}  # px/s², px/s


def background_shift(frames: Iterable[np.ndarray]) -> np.ndarray:
    """Apparent background shift per frame (T, 2) in px (x, y; frame n relative to n−1), row 0 = 0.
    A frame where fewer than 3 background corners are tracked gets NaN (treated as unknown)."""
    shifts = [np.zeros(2)]
    prev = None
    for frame in frames:
        g = to_gray(frame)
        if prev is not None:
            shifts.append(frame_shift(prev, g))
        prev = g
    if prev is None:
        raise ValueError("frames is empty: a video needs at least one frame")
    return np.vstack(shifts)


def frame_shift(prev: np.ndarray, cur: np.ndarray) -> np.ndarray:
    """Apparent background shift (2,) px from grey frame ``prev`` to grey frame ``cur`` (NaN if unknown)."""
    p0 = cv2.goodFeaturesToTrack(prev, _MAX_CORNERS, 0.01, 7)
    if p0 is None or len(p0) < 3:
        return np.full(2, np.nan)
    # OpenCV's stubs type nextPts as required; None (OpenCV allocates it) is its documented Python use
    p1, status, _ = cv2.calcOpticalFlowPyrLK(prev, cur, p0, None, winSize=(21, 21), maxLevel=3)  # type: ignore[call-overload]
    ok = status[:, 0] == 1
    if ok.sum() < 3:
        return np.full(2, np.nan)
    _, inliers = cv2.estimateAffinePartial2D(p0[ok], p1[ok], method=cv2.RANSAC, ransacReprojThreshold=_RANSAC_PX)
    if inliers is None or inliers.sum() < 3:
        return np.full(2, np.nan)
    return (p1[ok] - p0[ok])[inliers[:, 0] == 1, 0].mean(axis=0).astype(float)


def camera_offset(shift: np.ndarray) -> np.ndarray:
    """Camera offset o (T, 2) px relative to frame 0 from per-frame shifts: o_n = −Σ_{k≤n} d_k (NaN shifts
    count as 0), so that a static scene point seen at image position q_n satisfies q_n + o_n = const."""
    return -np.cumsum(np.nan_to_num(shift), axis=0)


def background_velocity(shift: np.ndarray, tau: float) -> np.ndarray:
    """The apparent background velocity *at* each frame (T, 2) px/s, the ``u`` of the eq. 17 UKF.

    ``d_n / τ`` is the mean velocity over [n−1, n], half a frame behind frame n (a visible lag under a
    shaking camera); the two last interval velocities are extrapolated linearly to frame n instead:
    u_n = (3 d_n − d_{n−1}) / (2τ). Frame 1 (one interval only) uses d_1 / τ; frame 0 is NaN (no motion
    seen yet), as are frames whose shift is unknown."""
    d = np.asarray(shift, dtype=float)
    u = np.full_like(d, np.nan)
    u[1:] = d[1:] / tau
    u[2:] = (3.0 * d[2:] - d[1:-1]) / (2.0 * tau)
    return u


def run_compensated(backend: str, y: np.ndarray, shift: np.ndarray, tau: float, **params: Any) -> np.ndarray:
    """Filter measured boxes ``y`` (T, 4) cx, cy, w, h px (NaN rows missing) of a moving camera whose
    background shift per frame is ``shift`` (T, 2) px. Returns image-coordinate states (T, 8)
    [cx, cy, w, h, velocities in px/s].

    ``backend="ukf"`` runs eq. 17's camera-augmented UKF with u = :func:`background_velocity` (``sigma_c``,
    ``sigma_u`` default to :data:`UKF_CAMERA`); any other back end runs in stabilised coordinates (eq. 18's
    camera-velocity input)."""
    y = np.asarray(y, dtype=float)
    shift = np.asarray(shift, dtype=float)
    if y.ndim != 2 or y.shape[1] != 4 or shift.shape != (len(y), 2):
        raise ValueError(f"y {y.shape} and shift {shift.shape}; allowed: (T, 4) and (T, 2)")
    model = filters.constant_velocity(tau, ndim=4)
    if backend == "ukf":
        ukf = filters.make("ukf", model, camera_motion=True, **{**UKF_CAMERA, **params})
        return ukf.run(y, u=background_velocity(shift, tau))
    offset = camera_offset(shift)
    z = y.copy()
    z[:, :2] += offset
    states = filters.make(backend, model, **params).run(z)
    states[:, :2] -= offset
    states[:, 4:6] += np.nan_to_num(shift) / tau  # image velocity = stabilised velocity − ȯ, ȯ_n = −d_n / τ
    return states
