"""Run a back end on one episode for many candidate parameter sets at once, and score the estimates."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

import filters
from envs import metrics
from envs.actions import ACCEPTS
from envs.boxes import cxcywh_to_xywh

SCORE_KEYS = ("rmse", "iou_mean", "success_auc", "precision20", "iou_precision")


@lru_cache(maxsize=64)
def box_model(tau: float) -> filters.StateSpaceModel:
    """The (cx, cy, w, h) constant-velocity model at frame interval ``tau`` (cached: models are immutable)."""
    return filters.constant_velocity(tau, ndim=4)


def run_positions(backend: str, y: np.ndarray, tau: float, params: dict[str, np.ndarray]) -> np.ndarray:
    """Filter the measured boxes ``y`` (T, 4) once per candidate: ``params`` maps names to arrays (A,);
    only the parameters ``backend`` accepts are passed. Returns position estimates (A, T, 4) cx, cy, w, h."""
    n = len(next(iter(params.values())))
    used = {k: params[k] for k in ACCEPTS[backend]}
    flt = filters.make(backend, box_model(tau), **used)
    states = flt.run(np.broadcast_to(y, (n, *y.shape)))
    return states[..., :4]


def score_estimates(est: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """Scores of estimates (A, T, 4) against the truth (T, 4), both cx, cy, w, h; each value (A,).

    ``rmse``: sqrt(mean over frames of the squared Euclidean error of (cx, cy, w, h)) in px
    (:func:`envs.metrics.rmse_total`); ``iou_mean``; ``success_auc``, ``precision20`` and
    ``iou_precision`` (seed 001's TP/(TP+FP), averaged over its 21 IoU thresholds) with the conventions of
    :mod:`envs.metrics` — computed here from one IoU and one centre-error pass (the tests check equality
    with the metric functions). Frames without ground truth are left out; a missing estimate where the
    truth exists counts as a failure (IoU 0, infinite centre error) and is not a detection, and is left
    out of the RMSE (filters have no estimate before a track's first finite measurement — the same frames
    for every candidate, so RMSEs stay paired)."""
    valid = np.isfinite(truth).all(axis=1)
    est_v, truth_v = est[:, valid], truth[valid]
    detected = np.isfinite(est_v).all(axis=-1)
    # before a track's first finite measurement no filter has an estimate (the same frames for every
    # candidate and for the rule): those frames are left out of the RMSE and count as IoU failures
    with_estimate = detected.all(axis=0)
    rmse = metrics.rmse_total(est_v[:, with_estimate], truth_v[with_estimate])
    pred_xywh, gt_xywh = cxcywh_to_xywh(est_v), cxcywh_to_xywh(truth_v)
    overlap = np.where(detected, metrics.iou(pred_xywh, gt_xywh), 0.0)  # (A, n)
    centre = np.where(detected, metrics.center_error(pred_xywh, gt_xywh), np.inf)
    n = max(int(valid.sum()), 1)
    # per frame, the number of the 21 IoU thresholds below (success: IoU > t, strict as the OTB toolkit) and
    # at or below (seed 001 true positive: IoU >= t) the frame's IoU; averaging these counts over frames and
    # thresholds is the mean over thresholds of the per-threshold rates
    below = np.searchsorted(metrics.SUCCESS_THRESHOLDS, overlap, side="left")
    at_or_below = np.where(detected, np.searchsorted(metrics.SUCCESS_THRESHOLDS, overlap, side="right"), 0)
    n_thresholds = len(metrics.SUCCESS_THRESHOLDS)
    n_detected = detected.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        iou_precision = np.where(n_detected > 0, at_or_below.sum(axis=1) / (n_thresholds * np.maximum(n_detected, 1)), np.nan)
    return {
        "rmse": rmse,
        "iou_mean": overlap.sum(axis=1) / n,
        "success_auc": below.sum(axis=1) / (n_thresholds * n),
        "precision20": (centre <= metrics.PRECISION_AT).sum(axis=1) / n,
        "iou_precision": iou_precision,
    }


def reward_from(scores: dict[str, np.ndarray], rule: dict[str, float], kind: str) -> np.ndarray:
    """The env reward for candidates' ``scores`` against the rule's: ``rmse`` → log(RMSE_rule / RMSE)
    (scale-free: 0 = as good as the rule, +0.1 ≈ 10 % lower RMSE); ``iou_precision`` / ``success_auc`` →
    candidate minus rule."""
    if kind == "rmse":
        return np.log(rule["rmse"] / np.maximum(scores["rmse"], 1e-300))
    return scores[kind] - rule[kind]
