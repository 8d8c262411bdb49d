"""OTB-standard tracking scores and the seed-001 IoU precision / F-score, as pure batched functions.

Conventions shared by every function here:

* **Boxes** are (..., 4) float arrays in **xywh** (x, y top-left, w, h, pixels) with **continuous areas**,
  as got10k: a box covers [x, x + w) × [y, y + h). For integer OTB boxes this equals the OTB toolkit's
  inclusive pixel count. A box with w <= 0 or h <= 0 has zero area (IoU 0 with anything).
* **Sequences** are (..., T, 4): the frame axis is the second-to-last one; leading axes are a batch. Sequences of
  different lengths go through :func:`score_sequences`.
* **Frame 1 counts** with the tracker's own frame-1 box (as in the OTB toolkit's one-pass evaluation, where
  frame 1 is the initial box). Slice the inputs if a score should start later. got10k's ``ExperimentOTB``
  instead overwrites frame 1 with the ground truth (``boxes[0] = anno[0]``); where a tracker stores a different
  initial box (SiamBAN and SiamRPN++ shift it by +0.5 px, STRUCK has its own sub-pixel box) a sequence of T frames can differ
  by up to 1/T.
* **Missing ground truth** (a NaN row; the loaders turn zero-size boxes such as the last frames of Board and
  Twinnings into NaN) is excluded from numerator and denominator. The OTB / pysot / got10k toolkits instead
  keep these frames in the denominator as failures, which changes a sequence's rates by at most 1/T: 1/472 on
  Twinnings (T = 472), 1/698 on Board. Measured against got10k's conventions (both differences) on the 13
  OTB-100 trackers of ``shared/data/otb``: per sequence ``|Δ success AUC| <= 1.7e-3`` and
  ``|Δ precision@20 px| <= 2.1e-3`` (= 1/472, Twinnings); the sequence means differ by <= 1.3e-4
  (``tests/scripts/test_otb_eval.py``).
* **Missing predictions** (a NaN row where the ground truth exists) count as failures: IoU 0 and centre error
  +inf. For :func:`rmse` a NaN estimate makes the result NaN (never silently dropped).
* A sequence with no valid ground-truth frame scores NaN.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

SUCCESS_THRESHOLDS = np.linspace(0.0, 1.0, 21)  # IoU thresholds 0, 0.05, …, 1 (OTB success plot)
PRECISION_THRESHOLDS = np.arange(0.0, 51.0)  # px, centre-error thresholds 0, 1, …, 50 (OTB precision plot)
PRECISION_AT = 20.0  # px, the OTB precision score threshold


def _numbers(name: str, values: ArrayLike) -> np.ndarray:
    """``values`` as a float array (ValueError naming ``name`` for what is not numbers)."""
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} is not an array of numbers ({err})") from None


def _thresholds(name: str, values: ArrayLike, low: float, high: float) -> np.ndarray:
    """Thresholds as a 1-D float array, each finite within [low, high] (ValueError naming ``name``)."""
    arr = _numbers(name, values)
    if arr.ndim > 1 or not (np.isfinite(arr) & (arr >= low) & (arr <= high)).all():
        raise ValueError(f"{name}={values!r}; allowed: a number or 1-D array of finite numbers in [{low:g}, {high:g}]")
    return np.atleast_1d(arr)


def _boxes(name: str, boxes: ArrayLike) -> np.ndarray:
    arr = _numbers(name, boxes)
    if arr.ndim < 1 or arr.shape[-1] != 4:
        raise ValueError(f"{name} has shape {arr.shape}; allowed: (..., 4) xywh boxes")
    return arr


def _check_sequences(names: tuple[str, str], a: np.ndarray, b: np.ndarray, layout: str) -> None:
    """Both arrays are sequences (rank >= 2) of broadcast-compatible shapes (ValueError naming them)."""
    if a.ndim < 2 or b.ndim < 2:
        raise ValueError(f"{names[0]} {a.shape} and {names[1]} {b.shape} must be sequences shaped {layout}")
    try:
        np.broadcast_shapes(a.shape, b.shape)
    except ValueError:
        raise ValueError(f"{names[0]} shape {a.shape} does not match {names[1]} shape {b.shape}") from None


def _pair(pred: ArrayLike, gt: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    p, g = _boxes("pred", pred), _boxes("gt", gt)
    _check_sequences(("pred", "gt"), p, g, "(..., T, 4)")
    return p, g


def _valid(boxes: np.ndarray) -> np.ndarray:
    """True where a box has no NaN (…, 4) → (…)."""
    return ~np.isnan(boxes).any(axis=-1)


def iou(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Intersection over union of xywh boxes, broadcast over leading axes: (..., 4), (..., 4) → (...).

    NaN where either box is NaN; 0 where both boxes are empty. Clipped to at most 1 (as got10k): rounding can
    make the IoU of two equal non-integer boxes 1 + 1e-14, which would pass the success threshold 1.0.

    >>> float(iou([0, 0, 2, 2], [1, 0, 2, 2]))
    0.3333333333333333
    """
    a, b = _boxes("a", a), _boxes("b", b)
    wa, ha = np.clip(a[..., 2], 0, None), np.clip(a[..., 3], 0, None)
    wb, hb = np.clip(b[..., 2], 0, None), np.clip(b[..., 3], 0, None)
    iw = np.minimum(a[..., 0] + wa, b[..., 0] + wb) - np.maximum(a[..., 0], b[..., 0])
    ih = np.minimum(a[..., 1] + ha, b[..., 1] + hb) - np.maximum(a[..., 1], b[..., 1])
    inter = np.clip(iw, 0, None) * np.clip(ih, 0, None)
    union = wa * ha + wb * hb - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(union > 0, np.minimum(inter / np.where(union > 0, union, 1.0), 1.0), 0.0)
    return np.where(_valid(a) & _valid(b), out, np.nan)


def center_error(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Euclidean distance (px) between box centres (x + w/2, y + h/2): (..., 4), (..., 4) → (...).

    NaN where either box is NaN.

    >>> float(center_error([0, 0, 2, 2], [3, 4, 2, 2]))
    5.0
    """
    a, b = _boxes("a", a), _boxes("b", b)
    d = (a[..., :2] + 0.5 * a[..., 2:]) - (b[..., :2] + 0.5 * b[..., 2:])
    return np.hypot(d[..., 0], d[..., 1])


def _scored_iou(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame IoU with missing predictions as 0, and the valid-ground-truth mask, both (..., T)."""
    valid = _valid(gt)
    o = iou(pred, gt)
    return np.where(valid, np.nan_to_num(o, nan=0.0), np.nan), valid


def _scored_center_error(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    valid = _valid(gt)
    e = center_error(pred, gt)
    return np.where(valid, np.nan_to_num(e, nan=np.inf), np.nan), valid


def _rate(hits: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fraction of valid frames that hit, over the frame axis: (..., T, n), (..., T) → (..., n)."""
    n = valid.sum(axis=-1)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, (hits & valid[..., None]).sum(axis=-2) / np.where(n > 0, n, 1), np.nan)


def success_curve(pred: ArrayLike, gt: ArrayLike, thresholds: ArrayLike = SUCCESS_THRESHOLDS) -> np.ndarray:
    """OTB success plot: fraction of frames with IoU > threshold (strict, as the OTB and pysot toolkits).

    (..., T, 4), (..., T, 4) → (..., n_thresholds)."""
    p, g = _pair(pred, gt)
    o, valid = _scored_iou(p, g)
    return _rate(o[..., None] > _thresholds("thresholds", thresholds, 0.0, 1.0), valid)


def success_auc(pred: ArrayLike, gt: ArrayLike) -> np.ndarray:
    """Area under the success plot = mean of :func:`success_curve` over the 21 thresholds 0, 0.05, …, 1.

    (..., T, 4), (..., T, 4) → (...).

    >>> gt = np.array([[0, 0, 10, 10], [0, 0, 10, 10]])
    >>> float(success_auc(gt, gt))
    0.9523809523809523
    """
    return success_curve(pred, gt).mean(axis=-1)


def precision_curve(pred: ArrayLike, gt: ArrayLike, thresholds: ArrayLike = PRECISION_THRESHOLDS) -> np.ndarray:
    """OTB precision plot: fraction of frames with centre error <= threshold (px).

    (..., T, 4), (..., T, 4) → (..., n_thresholds)."""
    p, g = _pair(pred, gt)
    e, valid = _scored_center_error(p, g)
    return _rate(e[..., None] <= _thresholds("thresholds", thresholds, 0.0, np.inf), valid)


def precision_score(pred: ArrayLike, gt: ArrayLike, threshold: float = PRECISION_AT) -> np.ndarray:
    """OTB precision score: fraction of frames with centre error <= 20 px. (..., T, 4) → (...)."""
    return precision_curve(pred, gt, _thresholds("threshold", threshold, 0.0, np.inf))[..., 0]


def _detection_counts(pred: np.ndarray, gt: np.ndarray, thresholds: ArrayLike):
    o, valid = _scored_iou(pred, gt)
    detected = valid & _valid(pred)
    tp = ((o[..., None] >= _thresholds("thresholds", thresholds, 0.0, 1.0)) & detected[..., None]).sum(axis=-2)
    return tp, detected.sum(axis=-1)[..., None], valid.sum(axis=-1)[..., None]


def iou_precision(pred: ArrayLike, gt: ArrayLike, thresholds: ArrayLike = SUCCESS_THRESHOLDS) -> np.ndarray:
    """[PaleRamon-BBox] precision TP / (TP + FP) per IoU threshold (eq. 2).

    A frame with valid ground truth and a prediction is a true positive when IoU >= threshold (the paper's
    "greater or equal"), else a false positive. Frames without a prediction are neither (they lower the recall
    of :func:`f_score`). (..., T, 4), (..., T, 4) → (..., n_thresholds); NaN if there is no prediction."""
    p, g = _pair(pred, gt)
    tp, n_pred, _ = _detection_counts(p, g, thresholds)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n_pred > 0, tp / np.where(n_pred > 0, n_pred, 1), np.nan)


def f_score(pred: ArrayLike, gt: ArrayLike, thresholds: ArrayLike = SUCCESS_THRESHOLDS) -> np.ndarray:
    """[PaleRamon-BBox] F-score (eq. 4) per IoU threshold: F = 2 P R / (P + R), P = :func:`iou_precision`,
    R = TP / (frames with valid ground truth); F = 0 where P + R = 0.

    (..., T, 4), (..., T, 4) → (..., n_thresholds)."""
    p, g = _pair(pred, gt)
    tp, n_pred, n_gt = _detection_counts(p, g, thresholds)
    with np.errstate(invalid="ignore", divide="ignore"):
        precision = np.where(n_pred > 0, tp / np.where(n_pred > 0, n_pred, 1), np.nan)
        recall = np.where(n_gt > 0, tp / np.where(n_gt > 0, n_gt, 1), np.nan)
        total = precision + recall
        return np.where(total > 0, 2 * precision * recall / np.where(total > 0, total, 1), 0.0)


def _errors(est: ArrayLike, truth: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    e, t = _numbers("est", est), _numbers("truth", truth)
    _check_sequences(("est", "truth"), e, t, "(..., T, M)")
    valid = ~np.isnan(t)
    return np.where(valid, e - np.where(valid, t, 0.0), 0.0), valid


def rmse(est: ArrayLike, truth: ArrayLike) -> np.ndarray:
    """Root-mean-square error per coordinate over frames with finite truth: (..., T, M) → (..., M).

    Any coordinate system (positions, cxcywh, xywh); NaN truth entries are skipped; a NaN estimate where the
    truth exists makes that coordinate's RMSE NaN.

    >>> rmse([[1.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [0.0, 2.0]]).tolist()
    [1.0, 1.4142135623730951]
    """
    err, valid = _errors(est, truth)
    n = valid.sum(axis=-2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(np.where(n > 0, (err**2).sum(axis=-2) / np.where(n > 0, n, 1), np.nan))


def rmse_total(est: ArrayLike, truth: ArrayLike) -> np.ndarray:
    """Overall (Euclidean) RMSE sqrt(Σ_c MSE_c) = sqrt(mean_t Σ_c e²_tc): (..., T, M) → (...).

    For positions this is the RMS distance in pixels ([Mo-FIR]'s "RMSE between real and predicted position")."""
    return np.sqrt((rmse(est, truth) ** 2).sum(axis=-1))


@dataclass(frozen=True, eq=False)
class SequenceScores:
    """Per-sequence OTB scores for S sequences; the benchmark figure is the mean over sequences."""

    success_curve: np.ndarray  # (S, 21) success rate at IoU thresholds 0…1
    precision_curve: np.ndarray  # (S, 51) precision at centre-error thresholds 0…50 px
    n_frames: np.ndarray  # (S,) frames with valid ground truth

    @property
    def success_auc(self) -> np.ndarray:
        """(S,) area under each sequence's success plot."""
        return self.success_curve.mean(axis=-1)

    @property
    def precision20(self) -> np.ndarray:
        """(S,) precision at 20 px."""
        return self.precision_curve[:, int(PRECISION_AT)]

    def mean(self) -> dict[str, float]:
        """Sequence-averaged ``success_auc`` and ``precision20`` (the OTB-100 table entries)."""
        return {"success_auc": float(self.success_auc.mean()), "precision20": float(self.precision20.mean())}


def score_sequences(preds: Sequence[ArrayLike], gts: Sequence[ArrayLike]) -> SequenceScores:
    """Score ragged sequences at once: ``preds[i]`` and ``gts[i]`` are (T_i, 4) xywh, T_i >= 1.

    All frames are concatenated and scored in one vectorised pass; per-sequence rates follow the module
    conventions (missing ground truth excluded, missing predictions are failures)."""
    if len(preds) != len(gts) or len(gts) == 0:
        raise ValueError(f"got {len(preds)} predictions for {len(gts)} ground truths; need equal counts >= 1")
    p_list = [_boxes(f"preds[{i}]", p) for i, p in enumerate(preds)]
    g_list = [_boxes(f"gts[{i}]", g) for i, g in enumerate(gts)]
    lengths = np.array([len(g) for g in g_list])
    for i, (p, g) in enumerate(zip(p_list, g_list, strict=False)):
        if p.shape != g.shape or p.ndim != 2 or len(g) == 0:
            raise ValueError(f"sequence {i}: pred shape {p.shape} and gt shape {g.shape} must be equal (T >= 1, 4)")
    p_all, g_all = np.concatenate(p_list), np.concatenate(g_list)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    o, valid = _scored_iou(p_all, g_all)
    e, _ = _scored_center_error(p_all, g_all)
    n = np.add.reduceat(valid.astype(np.int64), starts)
    hits_iou = np.add.reduceat((o[:, None] > SUCCESS_THRESHOLDS) & valid[:, None], starts, axis=0)
    hits_err = np.add.reduceat((e[:, None] <= PRECISION_THRESHOLDS) & valid[:, None], starts, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = np.where(n > 0, n, 1)[:, None]
        succ = np.where(n[:, None] > 0, hits_iou / denom, np.nan)
        prec = np.where(n[:, None] > 0, hits_err / denom, np.nan)
    return SequenceScores(success_curve=succ, precision_curve=prec, n_frames=n)
