"""The SORT-style tracker: equal to published SORT with SORT's filter, the options, and the filter bank's engines."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.agents.smoothing.tuner import load_pretrained
from bboxtune.agents.tracking.filter_bank import FilterBank
from bboxtune.agents.tracking.retune import CausalRetune
from bboxtune.agents.tracking.sort_tracker import Tracker, TrackerConfig, make_tracker
from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.data.mot_io import read_detections

from .sort_reference import sort_reference

MOT_ROOT = os.environ.get("MOT_ROOT")
needs_mot = pytest.mark.skipif(not MOT_ROOT, reason="MOT_ROOT is not set (CI sets it)")


def _detections(sequence: str, last_frame: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    det = read_detections(Path(MOT_ROOT or "") / sequence / "det" / "det.txt")
    keep = det.frame <= (last_frame or det.frame.max())
    return det.frame[keep], det.box[keep], det.score[keep]


def _rows(tracker: Tracker, frames: np.ndarray, boxes: np.ndarray, scores: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    return [(r.frame, int(i), b) for r in tracker.run(frames, boxes, scores) for i, b in zip(r.ids, r.boxes, strict=True)]


@needs_mot
@pytest.mark.parametrize(("sequence", "last", "max_age", "min_hits"), [("KITTI-13", None, 1, 3), ("ADL-Rundle-6", 150, 3, 2)])
def test_the_tracker_with_sorts_filter_is_sort(sequence: str, last: int | None, max_age: int, min_hits: int) -> None:
    frames, boxes, scores = _detections(sequence, last)
    ours = _rows(Tracker(FilterBank("sort_kf", 0.1), TrackerConfig(max_age=max_age, min_hits=min_hits)),
                 frames, boxes, scores)
    reference = sort_reference(frames, boxes, max_age=max_age, min_hits=min_hits)
    assert len(reference) > 200
    assert sorted((f, i) for f, i, _ in ours) == sorted((f, i) for f, i, _ in reference)
    want = {(f, i): b for f, i, b in reference}
    np.testing.assert_allclose(np.array([b for *_, b in sorted(ours, key=lambda r: r[:2])]),
                               np.array([want[k] for k in sorted(want)]), rtol=1e-9, atol=1e-7)


def _toy() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two objects moving right for 12 frames; object B's detection in frames 5–7 has a low score."""
    frames, boxes, scores = [], [], []
    for t in range(1, 13):
        for k, (x, y) in enumerate(((10.0, 10.0), (200.0, 50.0))):
            frames.append(t)
            boxes.append([x + 3 * t, y, 20.0, 40.0])
            scores.append(0.3 if (k == 1 and 5 <= t <= 7) else 0.9)
    return np.array(frames), np.array(boxes), np.array(scores)


def test_two_stage_keeps_a_track_through_low_score_detections() -> None:
    frames, boxes, scores = _toy()
    config = TrackerConfig(min_hits=1, two_stage=True, high_score=0.5, low_score=0.1, new_track_score=0.6)
    rows = _rows(Tracker(FilterBank("bytetrack_kf", 1 / 30), config), frames, boxes, scores)
    assert {i for _, i, _ in rows} == {1, 2}  # the low-score frames matched track 2: no new identity
    assert len(rows) == 24
    dropped = _rows(Tracker(FilterBank("bytetrack_kf", 1 / 30), TrackerConfig(min_hits=1, two_stage=True, low_score=0.5,
                                                                              high_score=0.5)), frames, boxes, scores)
    assert {i for _, i, _ in dropped} == {1, 2, 3}  # below low_score: dropped, the track ends, B is born again
    plain = _rows(Tracker(FilterBank("bytetrack_kf", 1 / 30), TrackerConfig(min_hits=1)), frames, boxes, scores)
    assert len(plain) == 24 and {i for _, i, _ in plain} == {1, 2}  # SORT association ignores scores


@pytest.mark.parametrize(("backend", "params"), [("kf", {"sigma_w": 300.0, "sigma_v": 3.0}),
                                                 ("ufir_cmn", {"psi": 0.3, "horizon": 6}), ("bytetrack_kf", {})])
def test_a_bank_track_equals_the_back_end_run_on_its_detections(backend: str, params: dict) -> None:
    rng = np.random.default_rng(5)
    y = np.cumsum(rng.normal(0, 2, (30, 4)), axis=0) + [100.0, 80.0, 30.0, 60.0]  # xywh
    y[[4, 9, 10, 17]] = np.nan
    bank = FilterBank(backend, 1 / 30, params)
    got = [bank.start(y[:1])[0]] + [bank.update(y[t:t + 1])[0] for t in range(1, 30)]
    f = filters.make(backend, filters.constant_velocity(1 / 30, ndim=4), **params)
    want = cxcywh_to_xywh(f.positions(xywh_to_cxcywh(y)))
    np.testing.assert_allclose(np.array(got), want, rtol=1e-9, atol=1e-7)


@pytest.mark.parametrize("kwargs", [{"max_age": -1}, {"min_hits": 2.5}, {"iou_threshold": 0.0}, {"iou_threshold": 1.5},
                                    {"low_iou_threshold": float("nan")}, {"high_score": float("inf")},
                                    {"two_stage": True, "low_score": 0.9, "high_score": 0.5}, {"max_age": True}])
def test_bad_settings_are_refused(kwargs: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs)) if "two_stage" not in kwargs else "low_score"):
        TrackerConfig(**kwargs)


@needs_mot
def test_tuned_tracking_is_causal() -> None:
    frames, boxes, scores = _detections("KITTI-13", 120)
    tuner = load_pretrained("mot15_det")

    def tracked(last: int) -> list[tuple[int, int, np.ndarray]]:
        keep = frames <= last
        retune = CausalRetune(tuner, 0.1, window=10)
        stock = filters.filter_class("bytetrack_kf").DEFAULTS
        bank = FilterBank("bytetrack_kf", 0.1, {name: stock[name] for name in tuner.parameters})
        rows = _rows(Tracker(bank, TrackerConfig(max_age=5), retune), frames[keep], boxes[keep], scores[keep])
        assert retune.calls > 0
        return rows

    full, cut = tracked(120), tracked(80)
    early = [r for r in full if r[0] <= 80]
    assert [(f, i) for f, i, _ in early] == [(f, i) for f, i, _ in cut]
    np.testing.assert_array_equal(np.array([b for *_, b in early]), np.array([b for *_, b in cut]))



@pytest.mark.parametrize("name", ["sort_kf", "bytetrack_kf", "kf", "ufir_cmn", "search"])
@pytest.mark.parametrize("bad", [np.inf, np.nan, 1e300, 2e7, -5.0, 0.0])
def test_a_bad_detection_is_refused_naming_its_row_whatever_the_filter(name: str, bad: float) -> None:
    tracker = make_tracker(name, 0.1)
    boxes = np.array([[10.0, 10.0, 5.0, 8.0], [50.0, 50.0, 5.0, 8.0]])
    for t in range(8):  # live tracks (and, for search, re-tuned ones) before the bad frame
        tracker.step(boxes + t, np.ones(2))
    broken = boxes + 8
    broken[1, 2] = bad
    with pytest.raises(ValueError, match=r"boxes\[1\] = .*allowed: finite x, y and w, h > 0"):
        tracker.step(broken, np.ones(2))
    frames = np.array([1, 1, 2])
    with pytest.raises(ValueError, match=r"boxes\[2\]"):
        list(make_tracker(name, 0.1).run(frames, np.vstack([boxes, broken[1:]]), np.ones(3)))
    with pytest.raises(ValueError, match=r"scores\[0\] = nan"):
        tracker.step(boxes, np.array([np.nan, 1.0]))
