"""The SORT-style tracker: equal to published SORT with SORT's filter, the options, and the filter bank's engines."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from bboxtune.agents.tracking.filter_bank import FilterBank
from bboxtune.agents.tracking.sort_tracker import Tracker, TrackerConfig
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
