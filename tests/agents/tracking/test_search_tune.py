"""The tracker's causal prediction search: candidate scores equal a per-candidate online reference, SORT's filter is
the stock candidate bit for bit, the tracker stays causal, bad settings are refused with one line."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.agents.tracking.filter_bank import FilterBank
from bboxtune.agents.tracking.search_tune import (
    CausalSearch,
    SearchSettings,
    candidate_grid,
    candidate_scores,
    predicted_boxes,
)
from bboxtune.agents.tracking.sort_tracker import SEARCH, Tracker, make_tracker
from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.data.metrics import iou
from bboxtune.filters.box_online import OnlineBoxKF
from bboxtune.filters.sort_kf import ScaledSortKF

TAU = 1 / 30
MODEL = filters.constant_velocity(TAU, ndim=4)


def _histories(n: int = 4, T: int = 30, seed: int = 3) -> np.ndarray:
    """n accelerating walkers' detections (n, T, 4) xywh with gaps; track i starts at frame i."""
    rng = np.random.default_rng(seed)
    velocity = np.cumsum(rng.normal(0, 0.6, (n, T, 4)) * [1, 1, 0.1, 0.2], axis=1)
    y = np.cumsum(velocity, axis=1) + [200.0, 150.0, 40.0, 90.0]
    y[rng.random((n, T)) < 0.2] = np.nan
    for i in range(n):
        y[i, :i] = np.nan
    return y


def _reference_scores(y: np.ndarray, params: dict[str, float]) -> float:
    """Mean IoU of the boxes the tracker's own engine predicts, one track at a time, with the detections."""
    ious = []
    online: OnlineBoxKF | None = None
    for box in xywh_to_cxcywh(y):
        if online is None:
            if not np.isnan(box[0]):
                online = OnlineBoxKF(ScaledSortKF(MODEL, **params))
                online.start(box[None])
            continue
        if not np.isnan(box[0]):
            ious.append(float(np.nan_to_num(iou(cxcywh_to_xywh(online.predict())[0], cxcywh_to_xywh(box)))))
        online.update(box[None])
    return float(np.mean(ious)) if ious else float("nan")


def test_candidate_scores_equal_each_candidate_run_alone() -> None:
    y = _histories()
    grid = candidate_grid(4.0, 3)
    scores, counts = candidate_scores(ScaledSortKF(MODEL), y, grid)
    assert scores.shape == (4, 9) and counts.tolist() == [int(np.isfinite(h[:, 0]).sum()) - 1 for h in y]
    for i in range(len(y)):
        for c in range(9):
            want = _reference_scores(y[i], {name: float(values[c]) for name, values in grid.items()})
            assert scores[i, c] == pytest.approx(want, rel=1e-12, abs=1e-12)
    assert np.ptp(scores, axis=1).min() > 1e-3  # the candidates differ: the comparison could fail


def test_the_stock_candidate_is_sorts_filter() -> None:
    y = _histories()
    ours = ScaledSortKF(MODEL).run(xywh_to_cxcywh(y))
    np.testing.assert_array_equal(ours, filters.make("sort_kf", MODEL).run(xywh_to_cxcywh(y)))
    boxes, scored = predicted_boxes(ScaledSortKF(MODEL), y)
    assert not scored[:, 0].any() and np.isfinite(boxes[scored]).all()


def _walkers(frames: int = 90, seed: int = 11) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Six crossing walkers with missed detections, as tracker input (frames, boxes, scores)."""
    rng = np.random.default_rng(seed)
    start = rng.uniform([50, 50], [600, 400], (6, 2))
    speed = rng.normal(0, 4, (6, 2))
    rows = []
    for t in range(1, frames + 1):
        for k in range(6):
            if rng.random() < 0.85:
                x, y = start[k] + speed[k] * t + rng.normal(0, 2, 2) + 10 * np.sin(t / (6 + k))
                rows.append((t, x, y, 30 + rng.normal(0, 1), 70 + rng.normal(0, 2)))
    data = np.array(rows)
    return data[:, 0].astype(np.int64), data[:, 1:], np.ones(len(data))


def _tracked(frames: np.ndarray, boxes: np.ndarray, scores: np.ndarray, last: int, settings: SearchSettings
             ) -> tuple[list[tuple[int, int, np.ndarray]], CausalSearch]:
    keep = frames <= last
    search = CausalSearch(TAU, settings)
    tracker = Tracker(FilterBank("sort_kf_scaled", TAU), retune=search)
    rows = [(r.frame, int(i), b) for r in tracker.run(frames[keep], boxes[keep], scores[keep])
            for i, b in zip(r.ids, r.boxes, strict=True)]
    return rows, search


def test_search_tracking_is_causal() -> None:
    frames, boxes, scores = _walkers()
    settings = SearchSettings(window=5, min_scored=3)
    full, search = _tracked(frames, boxes, scores, 90, settings)
    cut, _ = _tracked(frames, boxes, scores, 60, settings)
    assert search.calls > 0
    early = [r for r in full if r[0] <= 60]
    assert [(f, i) for f, i, _ in early] == [(f, i) for f, i, _ in cut] and len(cut) > 200
    np.testing.assert_array_equal(np.array([b for *_, b in early]), np.array([b for *_, b in cut]))
    sort_rows = [(r.frame, int(i), b) for r in make_tracker("sort_kf", TAU).run(frames, boxes, scores)
                 for i, b in zip(r.ids, r.boxes, strict=True)]
    assert not np.array_equal(np.array([b for *_, b in full]), np.array([b for *_, b in sort_rows]))  # it re-tuned


@pytest.mark.parametrize("settings", [SearchSettings(window=5, min_scored=3, margin=1.0),
                                      SearchSettings(window=5, min_scored=3, cap=1e-3)])  # every candidate at the cap
def test_a_full_margin_or_a_tie_keeps_sorts_filter(settings: SearchSettings) -> None:
    frames, boxes, scores = _walkers()
    rows, search = _tracked(frames, boxes, scores, 90, settings)
    assert search.calls > 0
    sort_rows = [(r.frame, int(i), b) for r in make_tracker("sort_kf", TAU).run(frames, boxes, scores)
                 for i, b in zip(r.ids, r.boxes, strict=True)]
    assert [(f, i) for f, i, _ in rows] == [(f, i) for f, i, _ in sort_rows]
    np.testing.assert_array_equal(np.array([b for *_, b in rows]), np.array([b for *_, b in sort_rows]))


@pytest.mark.parametrize(("kwargs", "name"), [({"window": 0}, "window"), ({"history": 1}, "history"),
                                              ({"steps": 4}, "steps"), ({"steps": True}, "steps"),
                                              ({"width": 0.5}, "width"), ({"width": float("nan")}, "width"),
                                              ({"margin": -0.1}, "margin"), ({"min_scored": 0}, "min_scored")])
def test_bad_settings_are_refused(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=f"^{name}=.*allowed") as err:
        SearchSettings(**kwargs)
    assert "\n" not in str(err.value)


def test_bad_uses_are_refused() -> None:
    with pytest.raises(ValueError, match="takes no tuner and no params"):
        make_tracker(SEARCH, TAU, params={"velocity_noise_scale": 2.0})
    with pytest.raises(ValueError, match="search settings are for filter"):
        make_tracker("sort_kf", TAU, search=SearchSettings())
    with pytest.raises(ValueError, match="candidates has"):
        candidate_scores(ScaledSortKF(MODEL), _histories(), {"velocity_noise_scale": np.ones(3)})
    with pytest.raises(ValueError, match="y has shape"):
        predicted_boxes(ScaledSortKF(MODEL), np.ones((3, 4)))
    with pytest.raises(ValueError, match="velocity_noise_scale"):
        ScaledSortKF(MODEL, velocity_noise_scale=0.0)
