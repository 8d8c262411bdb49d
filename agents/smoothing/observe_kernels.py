"""A tuner's observation of one ``bytetrack_kf`` track in one compiled call.

:meth:`bboxtune.agents.smoothing.tuner.Tuner.observe` computes what a tuner sees of a track in five steps, each
with its own checks and numpy glue: the boxes as (cx, cy, w, h), the source's fixed rule (σ = the source's relative
σ × the box scale, N = N_opt), the rule's filter run on the detections, then the features. Inside a tracker that
re-tunes its tracks every few frames, that glue costs more than the arithmetic. For a ``bytetrack_kf`` tuner whose
rule scales with the box (the OTB and MOT sources) :func:`box_observation` runs the same steps in one kernel —
calling the kernels the steps call (:func:`bboxtune.envs.episodes.features_kernels.median_scale`,
:func:`bboxtune.filters.box_kf_kernels.bytetrack_positions`, :func:`bboxtune.envs.episodes.features_kernels.track_observations`)
and repeating the steps' few own operations in their order — so its results are the steps' bit for bit (tested). Where
a step would raise (a σ or τ outside its range, a filter failure) it returns ``valid`` False and the caller takes the
steps, which raise their errors.
"""

from __future__ import annotations

import math

import numpy as np

from bboxtune.envs.episodes.features_kernels import median_scale, track_observations
from bboxtune.filters import jit
from bboxtune.filters.box_kf_kernels import bytetrack_positions


@jit.kernel
def box_observation(xywh: np.ndarray, tau: float, rel_v: float, rel_w: float, stds: np.ndarray, size_min: float,
                    horizon_range: tuple[int, int], sigma_range: tuple[float, float], tau_range: tuple[float, float]
                    ) -> tuple[np.ndarray, np.ndarray, float, float, int, bool]:
    """The observation of the checked track ``xywh`` (T, 4) x, y, w, h px (NaN rows missing) at frame interval
    ``tau`` (s) for a ``bytetrack_kf`` tuner whose rule is σ_v, σ_w = ``rel_v``, ``rel_w`` × the box scale and whose
    rule filter runs with the five noise weights ``stds`` (5, 1) (``ByteTrackKF.PER_TRACK`` order, no gap policy).

    Returns the boxes (T, 4) cx, cy, w, h; the observation (20,) float64 (the features' float32 cast is the
    caller's); the rule's σ_v, σ_w and horizon N = round(N_opt) within ``horizon_range``; and whether every step
    succeeded (σ within ``sigma_range``, τ within ``tau_range``, a finite rule run): when False the other results are
    undefined. ``size_min``: the smallest box side the filter takes (a detection below it is no detection, as
    ``scoring.detections`` makes it)."""
    T = len(xywh)
    y = np.empty((1, T, 4))
    area = np.empty((1, T))
    for t in range(T):  # boxes.xywh_to_cxcywh
        y[0, t, 0] = xywh[t, 0] + 0.5 * xywh[t, 2]
        y[0, t, 1] = xywh[t, 1] + 0.5 * xywh[t, 3]
        y[0, t, 2], y[0, t, 3] = xywh[t, 2], xywh[t, 3]
        area[0, t] = y[0, t, 2] * y[0, t, 3]
    scale = median_scale(area)[0]  # features.box_scale
    sigma_v, sigma_w = rel_v * scale, rel_w * scale  # tuner.rule_nominal
    valid = (sigma_range[0] <= sigma_v <= sigma_range[1] and sigma_range[0] <= sigma_w <= sigma_range[1]
             and tau_range[0] <= tau <= tau_range[1])
    if not valid:
        return y[0], np.empty(0), sigma_v, sigma_w, 0, False
    horizon = np.rint(math.sqrt(12.0 * sigma_v / (tau**2 * sigma_w)))  # horizon.rule_horizon: round(N_opt) …
    horizon = min(max(horizon, horizon_range[0]), horizon_range[1])  # … within [K, N_max]
    detected = y.copy()  # scoring.detections
    for t in range(T):
        if detected[0, t, 2] < size_min or detected[0, t, 3] < size_min:
            detected[0, t, :] = np.nan
    rule = np.empty((1, T, 4))
    if not bytetrack_positions(detected, stds[0], stds[1], stds[2], stds[3], stds[4], size_min, rule):
        return y[0], np.empty(0), sigma_v, sigma_w, 0, False
    obs, valid = track_observations(y, rule, np.full(1, tau), np.full(1, sigma_v), np.full(1, sigma_w), sigma_range,
                                    tau_range)
    return y[0], obs[0], sigma_v, sigma_w, int(horizon), valid
