"""motmetrics' scores through bboxtune.agents.evaluation.mot_metrics: a hand-made two-identity case whose numbers
are derived by hand below, flag-0 ground truth, the IoU distance that stands in for motmetrics' ``iou_matrix``
(which calls ``np.asfarray``, gone in NumPy 2) and the scoped shim the comparison runs under."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import motmetrics as mm
import numpy as np
import pytest

from bboxtune.agents.evaluation import mot_metrics
from bboxtune.envs.data.mot_io import read_ground_truth, read_results

# Ground truth, 6 frames: identity 1 at (0, 0, 10, 10), identity 2 at (100, 0, 10, 10) in every frame; a flag-0 row
# (identity 3, frame 3) far from everything.
GT_ROWS = [f"{f},1,0,0,10,10,1,-1,-1,-1" for f in range(1, 7)] + [f"{f},2,100,0,10,10,1,-1,-1,-1" for f in range(1, 7)]
FLAG0_ROW = "3,3,300,0,10,10,0,-1,-1,-1"
# Results: track 10 follows identity 1 (frame 1 box 10x8: IoU 0.8, distance 0.2); track 20 has identity 2 in frames
# 1-3, track 30 takes it over in frame 4 (an ID switch), frame 5 is 10x5 (IoU exactly 0.5: still a match, distance
# 0.5), frame 6 is 5 px off (IoU 50/150 = 1/3 < 0.5: no match, so a miss of identity 2 and a false positive);
# track 40 in frame 2 overlaps nothing (a false positive).
RESULT_ROWS = (["1,10,0,0,10,8,1,-1,-1,-1"] + [f"{f},10,0,0,10,10,1,-1,-1,-1" for f in range(2, 7)]
               + [f"{f},20,100,0,10,10,1,-1,-1,-1" for f in range(1, 4)]
               + ["4,30,100,0,10,10,1,-1,-1,-1", "5,30,100,0,10,5,1,-1,-1,-1", "6,30,105,0,10,10,1,-1,-1,-1"]
               + ["2,40,300,300,10,10,1,-1,-1,-1"])

# By hand. GT = 12 counted boxes of 2 identities; matches: identity 1 in 6 frames, identity 2 in frames 1-5 (the one
# in frame 4 is the switch); FN = 1 (identity 2, frame 6), FP = 2 (track 40 frame 2, track 30 frame 6), IDSW = 1.
#   MOTA = 1 - (FN + FP + IDSW) / GT = 1 - 4/12 = 2/3
#   MOTP (motmetrics: mean distance 1 - IoU of the 11 matches) = (0.2 + 0.5) / 11
#   IDs: the best one-to-one assignment is 1 <-> 10 (6 frames), 2 <-> 20 (3 frames; 2 <-> 30 would give 2):
#   IDTP = 9; IDFN = 12 - 9 = 3; IDFP = 13 predictions - 9 = 4
#   IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN) = 18/25; IDP = 9/13; IDR = 9/12
#   tracked ratios 6/6 and 5/6, both >= 0.8: MT = 2, ML = 0; switches per identity = 1/2
EXPECTED = {"mota": 2 / 3, "motp": 0.7 / 11, "idf1": 18 / 25, "idp": 9 / 13, "idr": 9 / 12, "num_switches": 1,
            "switches_per_identity": 0.5, "mostly_tracked": 2, "mostly_lost": 0, "num_false_positives": 2,
            "num_misses": 1, "num_objects": 12, "num_unique_objects": 2}


def write_case(folder: Path, gt_rows: list[str], result_rows: list[str]) -> tuple[Path, Path]:
    """``folder/gt.txt`` and ``folder/res.txt`` with these lines."""
    folder.mkdir(parents=True, exist_ok=True)
    gt, res = folder / "gt.txt", folder / "res.txt"
    gt.write_text("\n".join(gt_rows) + "\n")
    res.write_text("\n".join(result_rows) + "\n")
    return gt, res


def assert_scores(row: mot_metrics.Scores, expected: dict[str, float | int]) -> None:
    assert list(row) == list(mot_metrics.COLUMNS)
    for name, value in expected.items():
        if name in mot_metrics.COUNTS:
            assert type(row[name]) is int and row[name] == value, name
        else:
            assert row[name] == pytest.approx(value, rel=1e-12, abs=1e-12), name


@contextmanager
def asfarray_shim() -> Iterator[None]:
    """``np.asfarray`` (removed in NumPy 2) while the block runs, only if NumPy lacks it; removed again after."""
    added = not hasattr(np, "asfarray")
    if added:
        np.asfarray = lambda a, dtype=float: np.asarray(a, dtype=dtype)  # type: ignore[attr-defined]
    try:
        yield
    finally:
        if added:
            del np.asfarray  # type: ignore[attr-defined]


def test_hand_made_two_identity_case(tmp_path: Path) -> None:
    gt, res = write_case(tmp_path, [*GT_ROWS, FLAG0_ROW], RESULT_ROWS)
    scores = mot_metrics.score_files({"hand": (gt, res)})
    assert list(scores) == ["hand", mot_metrics.OVERALL]
    assert_scores(scores["hand"], EXPECTED)
    assert_scores(scores[mot_metrics.OVERALL], EXPECTED)  # one sequence: the overall row is the same


def test_flag0_rows_change_nothing(tmp_path: Path) -> None:
    with_row = mot_metrics.score_files({"s": write_case(tmp_path / "a", [*GT_ROWS, FLAG0_ROW], RESULT_ROWS)})["s"]
    without = mot_metrics.score_files({"s": write_case(tmp_path / "b", GT_ROWS, RESULT_ROWS)})["s"]
    assert with_row == without
    assert with_row["num_unique_objects"] == 2  # identity 3 has only a flag-0 row: not counted


def test_a_box_on_a_flag0_pedestrian_is_a_false_positive(tmp_path: Path) -> None:
    """As motmetrics' MOT15 path and TrackEval's MOT15 do (no distractor removal for MOT15)."""
    on_flag0 = "3,50,300,0,10,10,1,-1,-1,-1"  # exactly on identity 3's flag-0 box
    row = mot_metrics.score_files({"s": write_case(tmp_path, [*GT_ROWS, FLAG0_ROW], [*RESULT_ROWS, on_flag0])})["s"]
    assert row["num_false_positives"] == EXPECTED["num_false_positives"] + 1
    assert row["num_objects"] == 12 and row["num_misses"] == 1


def test_overall_row_sums_the_counts_and_recomputes_the_ratios(tmp_path: Path) -> None:
    # sequence "b": identity 2 only, tracked perfectly by one track: 6 matches, nothing else
    b_gt, b_res = write_case(tmp_path / "b", GT_ROWS[6:], [f"{f},7,100,0,10,10,1,-1,-1,-1" for f in range(1, 7)])
    scores = mot_metrics.score_files({"a": write_case(tmp_path / "a", GT_ROWS, RESULT_ROWS), "b": (b_gt, b_res)})
    assert list(scores) == ["a", "b", mot_metrics.OVERALL]
    assert scores["b"]["mota"] == 1.0 and scores["b"]["num_switches"] == 0
    overall = scores[mot_metrics.OVERALL]
    # 18 boxes, 3 identities; FN 1, FP 2, IDSW 1: MOTA = 1 - 4/18; IDTP 9 + 6 = 15, IDFP 4, IDFN 3: IDF1 = 30/37
    assert_scores(overall, {"num_objects": 18, "num_unique_objects": 3, "num_switches": 1, "mota": 1 - 4 / 18,
                            "idf1": 30 / 37, "switches_per_identity": 1 / 3, "motp": 0.7 / 17})


@pytest.mark.filterwarnings("ignore:Operation with tuple is deprecated")  # motmetrics' loader on pandas 3
def test_the_same_scores_as_motmetrics_own_mot_challenge_evaluator(tmp_path: Path) -> None:
    """motmetrics' loader (ground truth with min_confidence=1, as its eval_motchallenge.py) and
    compare_to_groundtruth (its iou_matrix, so under the shim) give the numbers of our path."""
    gt, res = write_case(tmp_path, [*GT_ROWS, FLAG0_ROW], RESULT_ROWS)
    with asfarray_shim():
        acc = mm.utils.compare_to_groundtruth(mm.io.loadtxt(gt, fmt="mot15-2D", min_confidence=1),
                                              mm.io.loadtxt(res, fmt="mot15-2D"), "iou", distth=0.5)
    theirs = mot_metrics.score({"s": acc})["s"]
    ours = mot_metrics.score({"s": mot_metrics.accumulate(read_ground_truth(gt), read_results(res))})["s"]
    assert theirs == pytest.approx(ours, rel=1e-12, abs=1e-12)


def test_iou_distance_equals_motmetrics_iou_matrix() -> None:
    """The one stand-in for motmetrics code (module docstring of mot_metrics): same distances, same NaN pattern
    (IoU < 0.5 not allowed, IoU exactly 0.5 allowed), on random boxes and on the boundary."""
    rng = np.random.default_rng(36)
    gt = np.column_stack([rng.uniform(0, 50, (40, 2)), rng.uniform(1, 30, (40, 2))])
    hyp = np.vstack([gt[:20] + rng.normal(0, 3, (20, 4)).clip(-0.5, 0.5) * [1, 1, 0, 0], gt[20:] + [4, 0, 0, 0]])
    boundary_gt, boundary_hyp = np.array([[0.0, 0, 10, 10]]), np.array([[0.0, 0, 10, 5], [0.0, 0, 10, 4.9]])
    with asfarray_shim():
        for a, b in ((gt, hyp), (boundary_gt, boundary_hyp)):
            theirs = mm.distances.iou_matrix(a, b, max_iou=0.5)
            ours = mot_metrics.iou_distance(a, b)
            assert ours.shape == theirs.shape == (len(a), len(b))
            np.testing.assert_array_equal(np.isnan(ours), np.isnan(theirs))
            np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12)
        assert 0 < np.isnan(ours).sum() < ours.size or a is boundary_gt
    assert mot_metrics.iou_distance(boundary_gt, boundary_hyp)[0, 0] == 0.5  # allowed
    assert math.isnan(mot_metrics.iou_distance(boundary_gt, boundary_hyp)[0, 1])  # IoU 0.49: not allowed
    assert mot_metrics.iou_distance(np.empty((0, 4)), hyp).shape == (0, len(hyp))  # the accumulator's (N, K)


def test_the_asfarray_shim_does_not_leak_into_numpy() -> None:
    had = hasattr(np, "asfarray")
    with asfarray_shim():
        assert np.asfarray([1, 2]).dtype == np.float64  # type: ignore[attr-defined]
    assert hasattr(np, "asfarray") == had
    if not had:  # NumPy 2: motmetrics 1.4's iou_matrix fails without the shim, as the module docstring says
        assert "asfarray" in mm.distances.iou_matrix.__code__.co_names or mm.__version__ != "1.4.0"
        with pytest.raises(AttributeError, match="asfarray"):
            np.asfarray  # type: ignore[attr-defined]  # noqa: B018


def test_scoring_never_calls_np_asfarray(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Our path needs no shim: with an np.asfarray that fails, the hand case still scores (on NumPy 1 too)."""
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("np.asfarray called")

    monkeypatch.setattr(np, "asfarray", refuse, raising=False)
    row = mot_metrics.score_files({"s": write_case(tmp_path, GT_ROWS, RESULT_ROWS)})["s"]
    assert row["mota"] == pytest.approx(2 / 3)


def test_switches_per_identity_is_nan_without_identities(tmp_path: Path) -> None:
    row = mot_metrics.score_files({"s": write_case(tmp_path, [FLAG0_ROW], RESULT_ROWS[:1])})["s"]
    assert row["num_unique_objects"] == 0 and math.isnan(row["switches_per_identity"])
    assert row["num_false_positives"] == 1


def test_bad_input_names_the_file_and_line(tmp_path: Path) -> None:
    gt, res = write_case(tmp_path, GT_ROWS, [*RESULT_ROWS[:2], "3,10,0,0,0,10,1,-1,-1,-1"])
    with pytest.raises(ValueError, match=rf"{res}:3: box size w=0"):
        mot_metrics.score_files({"s": (gt, res)})
    with pytest.raises(ValueError, match=r"hyp_boxes has shape \(4,\); allowed: \(N, 4\)"):
        mot_metrics.iou_distance(np.zeros((1, 4)), np.zeros(4))
    with pytest.raises(ValueError, match="gt_boxes is not an array of numbers"):
        mot_metrics.iou_distance([["a", 1, 2, 3]], np.zeros((1, 4)))
    with pytest.raises(ValueError, match="OVERALL"):
        mot_metrics.score({mot_metrics.OVERALL: mm.MOTAccumulator()})
    with pytest.raises(ValueError, match="no sequences"):
        mot_metrics.score({})


def test_markdown_table() -> None:
    row = dict.fromkeys(mot_metrics.COLUMNS, 1)
    row.update(mota=2 / 3, motp=0.5, idf1=0.72, idp=1.0, idr=0.75, switches_per_identity=0.5)
    lines = mot_metrics.markdown_table({"KITTI-13": row}).splitlines()
    assert lines[0] == "| sequence | " + " | ".join(mot_metrics.COLUMNS) + " |"
    assert lines[2] == "| KITTI-13 | 0.667 | 0.500 | 0.720 | 1.000 | 0.750 | 1 | 0.500 | 1 | 1 | 1 | 1 | 1 | 1 |"
