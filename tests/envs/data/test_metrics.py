from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune.envs.data.metrics import (
    PRECISION_THRESHOLDS,
    SUCCESS_THRESHOLDS,
    center_error,
    f_score,
    iou,
    iou_precision,
    precision_curve,
    precision_score,
    rmse,
    rmse_total,
    score_sequences,
    success_auc,
    success_curve,
)


def pixel_iou(a, b, scale=1):
    """Independent IoU by counting the pixels of a (scale × finer) grid covered by two boxes."""
    grid = np.zeros((2, 64 * scale, 64 * scale), dtype=bool)
    for k, (x, y, w, h) in enumerate((a, b)):
        x0, y0, x1, y1 = (round(v * scale) for v in (x, y, x + max(w, 0), y + max(h, 0)))
        grid[k, y0 + 16 * scale : y1 + 16 * scale, x0 + 16 * scale : x1 + 16 * scale] = True
    union = (grid[0] | grid[1]).sum()
    return (grid[0] & grid[1]).sum() / union if union else 0.0


integer_box = st.tuples(*(st.integers(-10, 20),) * 2, *(st.integers(0, 12),) * 2)
half_box = st.tuples(*(st.integers(-20, 40).map(lambda v: v / 2),) * 2, *(st.integers(0, 24).map(lambda v: v / 2),) * 2)


@settings(max_examples=200, deadline=None)
@given(integer_box, integer_box)
def test_iou_matches_pixel_counting_on_integer_boxes(a, b):
    assert iou(a, b) == pytest.approx(pixel_iou(a, b), abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(half_box, half_box)
def test_iou_matches_pixel_counting_on_half_pixel_boxes(a, b):
    assert iou(a, b) == pytest.approx(pixel_iou(a, b, scale=2), abs=1e-12)


def test_iou_basic_cases_and_batching():
    a = np.array([[0, 0, 10, 10], [0, 0, 10, 10], [0, 0, 10, 10], [0, 0, 0, 0], [0, 0, 4, 4]], float)
    b = np.array([[0, 0, 10, 10], [20, 20, 5, 5], [5, 0, 10, 10], [0, 0, 0, 0], [1, 1, 2, 2]], float)
    np.testing.assert_allclose(iou(a, b), [1.0, 0.0, 50 / 150, 0.0, 4 / 16])
    np.testing.assert_allclose(iou(a, b), iou(b, a))
    assert iou(np.broadcast_to(a, (3, 5, 4)), b).shape == (3, 5)
    assert np.isnan(iou([np.nan, 0, 1, 1], [0, 0, 1, 1]))
    with pytest.raises(ValueError, match="shape"):
        iou([0, 0, 1], [0, 0, 1, 1])


def test_center_error():
    np.testing.assert_allclose(center_error([[0, 0, 4, 4], [0, 0, 2, 2]], [[3, 4, 4, 4], [0, 0, 4, 4]]),
                               [5.0, np.hypot(1, 1)])


def seq_with_ious():
    """Ground truth 10×10 boxes and predictions shifted so that IoU = 1, 0.6, 0.25, 0 (known values)."""
    gt = np.tile([0.0, 0.0, 10.0, 10.0], (4, 1))
    # a shift s along x gives IoU (10 − s) / (10 + s)
    shifts = [0.0, 2.5, 6.0, 20.0]
    pred = gt.copy()
    pred[:, 0] = shifts
    return pred, gt, np.array([1.0, 7.5 / 12.5, 4.0 / 16.0, 0.0]), np.array(shifts)


def test_success_curve_is_strictly_greater_and_auc_is_its_mean():
    pred, gt, ious, _ = seq_with_ious()
    np.testing.assert_allclose(iou(pred, gt), ious)
    curve = success_curve(pred, gt)
    expected = [(ious > t).mean() for t in SUCCESS_THRESHOLDS]
    np.testing.assert_allclose(curve, expected)
    assert curve[11] == 0.5 and curve[12] == 0.25  # IoU 0.6 > 0.6 is false (strict, as the OTB toolkit)
    assert success_auc(pred, gt) == pytest.approx(np.mean(expected))
    assert success_auc(gt, gt) == pytest.approx(20 / 21)  # a perfect tracker scores 20/21 (IoU 1 > 1 is false)


def test_precision_curve_is_inclusive():
    pred, gt, _, shifts = seq_with_ious()
    curve = precision_curve(pred, gt)
    np.testing.assert_allclose(curve, [(shifts <= t).mean() for t in PRECISION_THRESHOLDS])
    gt2 = np.tile([0.0, 0.0, 10.0, 10.0], (2, 1))
    pred2 = gt2 + [[20.0, 0, 0, 0], [20.0001, 0, 0, 0]]
    assert precision_score(pred2, gt2) == 0.5  # 20 px counts, 20.0001 px does not


def test_missing_ground_truth_excluded_and_missing_prediction_fails():
    pred, gt, ious, shifts = seq_with_ious()
    gt_missing = np.vstack([gt, [np.nan] * 4])
    pred_extra = np.vstack([pred, [0, 0, 10, 10]])
    np.testing.assert_allclose(success_curve(pred_extra, gt_missing), success_curve(pred, gt))
    np.testing.assert_allclose(precision_curve(pred_extra, gt_missing), precision_curve(pred, gt))
    pred_missing = pred.copy()
    pred_missing[0] = np.nan  # the perfect frame is now missing: a failure at every threshold
    np.testing.assert_allclose(success_curve(pred_missing, gt), [(ious[1:] > t).sum() / 4 for t in SUCCESS_THRESHOLDS])
    np.testing.assert_allclose(precision_curve(pred_missing, gt), [(shifts[1:] <= t).sum() / 4 for t in PRECISION_THRESHOLDS])
    assert np.isnan(success_auc(pred[:1], np.full((1, 4), np.nan)))


def test_batched_scores_equal_per_sequence_scores():
    rng = np.random.default_rng(3)
    gt = np.concatenate([rng.uniform(0, 100, (5, 30, 2)), rng.uniform(5, 50, (5, 30, 2))], axis=-1)
    pred = gt + rng.normal(0, 5, gt.shape)
    batched = success_auc(pred, gt), precision_score(pred, gt), f_score(pred, gt)
    for i in range(5):
        assert batched[0][i] == pytest.approx(success_auc(pred[i], gt[i]))
        assert batched[1][i] == pytest.approx(precision_score(pred[i], gt[i]))
        np.testing.assert_allclose(batched[2][i], f_score(pred[i], gt[i]))


def test_seed001_precision_and_f_score_by_hand():
    pred, gt, _, _ = seq_with_ious()  # IoU 1, 0.6, 0.25, 0
    pred[3] = np.nan  # no prediction on the last frame
    thr = [0.0, 0.5, 0.6, 1.0]
    # TP at IoU >= thr among 3 predictions; recall over 4 ground-truth frames
    tp = np.array([3, 2, 2, 1])
    np.testing.assert_allclose(iou_precision(pred, gt, thr), tp / 3)
    p, r = tp / 3, tp / 4
    np.testing.assert_allclose(f_score(pred, gt, thr), 2 * p * r / (p + r))
    assert f_score(pred + [100, 0, 0, 0], gt, [0.5])[0] == 0.0


def test_rmse_per_coordinate_total_and_missing():
    truth = np.array([[0.0, 0.0], [0.0, 0.0], [np.nan, np.nan]])
    est = np.array([[3.0, 0.0], [3.0, 4.0], [99.0, 99.0]])
    np.testing.assert_allclose(rmse(est, truth), [3.0, np.sqrt(8.0)])
    assert rmse_total(est, truth) == pytest.approx(np.sqrt(9.0 + 8.0))
    est[0, 0] = np.nan
    assert np.isnan(rmse(est, truth)[0]) and np.isfinite(rmse(est, truth)[1])
    assert rmse(np.zeros((2, 5, 3)), np.ones((2, 5, 3))).shape == (2, 3)


def test_score_sequences_ragged_matches_per_sequence():
    rng = np.random.default_rng(4)
    gts, preds = [], []
    for T in (3, 17, 40):
        g = np.concatenate([rng.uniform(0, 100, (T, 2)), rng.uniform(5, 50, (T, 2))], axis=1)
        gts.append(g)
        preds.append(g + rng.normal(0, 8, g.shape))
    gts[1][5] = np.nan
    preds[2][7] = np.nan
    scores = score_sequences(preds, gts)
    for i in range(3):
        assert scores.success_auc[i] == pytest.approx(success_auc(preds[i], gts[i]))
        assert scores.precision20[i] == pytest.approx(precision_score(preds[i], gts[i]))
    assert scores.n_frames.tolist() == [3, 16, 40]
    assert scores.mean()["success_auc"] == pytest.approx(scores.success_auc.mean())
    with pytest.raises(ValueError, match="sequence 1"):
        score_sequences([preds[0], preds[1][:-1]], gts[:2])
    with pytest.raises(ValueError, match="equal counts"):
        score_sequences(preds[:2], gts)


def test_mismatched_sequences_raise_naming_both_sides() -> None:
    with pytest.raises(ValueError, match="pred shape .* does not match gt shape"):
        success_auc(np.zeros((3, 4)), np.zeros((5, 4)))
    with pytest.raises(ValueError, match="est .* and truth .* must be sequences"):
        rmse(np.zeros(4), np.zeros((2, 4)))


def test_equal_non_integer_boxes_never_pass_the_iou_threshold_one():
    """Rounding can make the IoU of two equal 2-decimal boxes 1 + 1e-14; it is clipped to 1, so a perfect
    estimate scores 20/21 of the success plot (IoU > 1.0 never holds) in metrics and in the fused scorer."""
    from bboxtune.envs.data.boxes import xywh_to_cxcywh
    from bboxtune.envs.episodes.scoring import score_estimates

    boxes = np.round(np.random.default_rng(0).uniform(1.0, 300.0, (5000, 4)), 2)
    assert iou(boxes, boxes).max() <= 1.0
    assert success_auc(boxes, boxes) == pytest.approx(20 / 21, abs=0)
    centre = xywh_to_cxcywh(boxes)
    assert score_estimates(centre[None], centre)["success_auc"][0] == pytest.approx(20 / 21, abs=0)
