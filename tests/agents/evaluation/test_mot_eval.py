"""The MOT identity protocol (bboxtune.agents.evaluation.mot_eval): scored frame sets, per-identity scores, paired table rows."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune.agents.evaluation import mot_eval
from bboxtune.envs.data import metrics
from bboxtune.envs.data.boxes import cxcywh_to_xywh
from bboxtune.envs.episodes.actions import Nominal
from bboxtune.envs.episodes.episode import Episode

NOMINAL = Nominal(sigma_w=30.0, sigma_v=2.0, psi=0.0, horizon=10)


def _episode(measured: np.ndarray, T: int = 20) -> Episode:
    t = np.arange(T, dtype=float)
    truth = np.stack([100 + 2 * t, 50 + t, np.full(T, 20.0), np.full(T, 40.0)], axis=1)
    y = truth + 1.0
    y[~measured] = np.nan
    return Episode(truth=truth, y=y, tau=1 / 14, nominal=NOMINAL)


def test_box_iou_matches_metrics_and_scores_missing_as_zero() -> None:
    rng = np.random.default_rng(0)
    a = np.column_stack([rng.uniform(0, 50, (30, 2)), rng.uniform(1, 30, (30, 2))])
    b = a + rng.normal(0, 5, a.shape)
    b[:, 2:] = np.abs(b[:, 2:]) + 1
    np.testing.assert_allclose(mot_eval.box_iou(a, b), metrics.iou(cxcywh_to_xywh(a), cxcywh_to_xywh(b)), atol=1e-12)
    a[3] = np.nan
    assert mot_eval.box_iou(a, b)[3] == 0.0


def test_frame_sets_warmup_and_gaps() -> None:
    measured = np.zeros(20, dtype=bool)
    measured[[2, 3, 4, 9, 10, 11, 12, 15]] = True
    ep = _episode(measured)
    sets = mot_eval.frame_sets(ep)
    # detected: measured and at least WARMUP = 5 frames after the first detection (frame 2): 9, 10, 11, 12, 15
    assert np.flatnonzero(sets.detected).tolist() == [9, 10, 11, 12, 15]
    # gaps: between the first (2) and the last (15) detection, not measured
    assert np.flatnonzero(sets.gaps).tolist() == [5, 6, 7, 8, 13, 14]


def test_frame_sets_leave_out_frames_without_truth() -> None:
    measured = np.ones(20, dtype=bool)
    measured[8:11] = False
    ep = _episode(measured)
    truth = ep.truth.copy()
    truth[[9, 12]] = np.nan
    sets = mot_eval.frame_sets(Episode(truth=truth, y=ep.y, tau=ep.tau, nominal=NOMINAL))
    assert not sets.gaps[9] and sets.gaps[8] and not sets.detected[12] and sets.detected[13]


def test_identity_scores_raw_detections() -> None:
    measured = np.ones(20, dtype=bool)
    measured[10:14] = False
    ep = _episode(measured)
    scores = mot_eval.identity_scores(ep.y, ep)
    expected = metrics.iou(cxcywh_to_xywh(ep.y[5:10]), cxcywh_to_xywh(ep.truth[5:10]))[0]
    assert scores["iou_detected"] == pytest.approx(expected)
    assert scores["sq_detected"] == pytest.approx(4.0)  # every coordinate 1 px off
    assert scores["iou_gap_sum"] == 0.0 and scores["n_gap"] == 4.0


def test_paired_rows_reference_is_zero_against_itself_and_pools_gaps() -> None:
    rng = np.random.default_rng(1)
    episodes = []
    for _ in range(6):
        measured = rng.random(30) > 0.3
        measured[[0, -1]] = True
        episodes.append(_episode(measured, T=30))
    held = [mot_eval.backend_method("kf", {"sigma_w": 30.0, "sigma_v": 2.0})]
    scores = {"raw": mot_eval.score_method(mot_eval.raw_method, episodes),
              "kf": mot_eval.score_method(held[0], episodes)}
    rows = {r["method"]: r for r in mot_eval.paired_rows(scores, references=("raw",), n_boot=200)}
    assert rows["raw"]["d_iou_detected_vs_raw"].startswith("+0.000 [+0.000, +0.000]")
    assert rows["raw"]["iou_gaps"].startswith("0.000")
    pooled = scores["kf"]["iou_gap_sum"].sum() / scores["kf"]["n_gap"].sum()
    assert rows["kf"]["iou_gaps"].startswith(f"{pooled:.3f}")
    assert pooled > 0.5  # the KF predicts the straight-line motion through the gaps
    # clusters: all-distinct labels are the identity bootstrap; two clusters of three give other intervals
    assert mot_eval.paired_rows(scores, references=("raw",), n_boot=200, clusters=list("abcdef")) == list(rows.values())
    by_pair = {r["method"]: r for r in mot_eval.paired_rows(scores, references=("raw",), n_boot=200, clusters=list("aaabbb"))}
    assert by_pair["kf"]["iou_gaps"].startswith(f"{pooled:.3f}") and by_pair["kf"]["iou_gaps"] != rows["kf"]["iou_gaps"]
