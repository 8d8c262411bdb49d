"""MOT15 identity episodes: Hungarian matching, episodes with gaps, the split, detection statistics, the real copy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.data.metrics import iou
from bboxtune.envs.data.mot import (
    MATCH_IOU,
    MIN_DETECTIONS,
    MIN_FRAMES,
    MOTIdentity,
    detection_stats,
    holdout_split,
    load_identities,
    match_identities,
    resolve_root,
    split,
)
from bboxtune.envs.data.mot_io import Detections, GroundTruth, read_detections, read_ground_truth


def detections(rows: list[tuple[int, list[float]]], scores: list[float] | None = None) -> Detections:
    return Detections(frame=np.array([f for f, _ in rows], dtype=np.int64),
                      box=np.array([b for _, b in rows], float).reshape(-1, 4),
                      score=np.array(scores if scores is not None else [1.0] * len(rows)))


def ground_truth(rows: list[tuple[int, int, list[float], int]]) -> GroundTruth:
    return GroundTruth(frame=np.array([r[0] for r in rows], dtype=np.int64), id=np.array([r[1] for r in rows]),
                       box=np.array([r[2] for r in rows], float), flag=np.array([r[3] == 1 for r in rows]))


def line(frame: int, ident: int, box: list[float], last: float) -> str:
    return ",".join(map(str, [frame, ident, *box, last, -1, -1, -1]))


def make_root(root: Path, sequences: dict[str, tuple[int, int, list[str], list[str]]]) -> Path:
    """A MOT root: {name: (fps, frames, det lines, gt lines)}."""
    table = ["sequence,fps,frames"]
    for name, (fps, frames, det, gt) in sequences.items():
        for sub, lines in (("det", det), ("gt", gt)):
            (root / name / sub).mkdir(parents=True)
            (root / name / sub / f"{sub}.txt").write_text("\n".join(lines) + "\n")
        table.append(f"{name},{fps},{frames}")
    (root / "sequences.csv").write_text("\n".join(table) + "\n")
    return root


def test_documented_constants():
    assert (MATCH_IOU, MIN_FRAMES, MIN_DETECTIONS) == (0.5, 20, 10)


def test_root_resolution(tmp_path, monkeypatch):
    monkeypatch.delenv("MOT_ROOT", raising=False)
    with pytest.raises(ValueError, match="--mot-root DIR .* or set MOT_ROOT"):
        resolve_root(None)
    monkeypatch.setenv("MOT_ROOT", str(tmp_path))
    assert resolve_root(None) == tmp_path
    with pytest.raises(ValueError, match="does not exist"):
        resolve_root(tmp_path / "missing")
    with pytest.raises(ValueError, match="sequences.csv: cannot read"):
        load_identities()


# --- matching ---------------------------------------------------------------------------------------------------
# Boxes of height 10 along x: IoU(D1, G1) = 9.5/10.5 = 0.905, IoU(D1, G2) = 7.5/12.5 = 0.6,
# IoU(D2, G1) = 7/13 = 0.538, IoU(D2, G2) = 4/16 = 0.25.
G1, G2, D1, D2 = [0, 0, 10, 10], [3, 0, 10, 10], [0.5, 0, 10, 10], [-3, 0, 10, 10]


def greedy(det: Detections, gt: GroundTruth) -> np.ndarray:
    """Highest IoU first, per frame: the matching the Hungarian assignment must beat."""
    out = np.full(len(gt), -1)
    for frame in np.unique(gt.frame):
        pairs = sorted(((float(iou(det.box[d], gt.box[g])), d, g) for d in np.flatnonzero(det.frame == frame)
                        for g in np.flatnonzero(gt.frame == frame)), reverse=True)
        for overlap, d, g in pairs:
            if overlap >= 0.5 and out[g] < 0 and d not in out:
                out[g] = d
    return out


def test_hungarian_beats_greedy_and_frames_stay_apart():
    det = detections([(1, D1), (1, D2), (2, D1)])
    gt = ground_truth([(1, 1, G1, 1), (1, 2, G2, 1), (2, 1, G1, 1), (3, 1, G1, 1)])
    assert greedy(det, gt).tolist() == [0, -1, 2, -1]  # D1-G1 first leaves D2, G2 (IoU 0.25) unmatched
    assert match_identities(det, gt).tolist() == [1, 0, 2, -1]  # two pairs: D2-G1 and D1-G2; frame 3 has no det


def test_iou_threshold_edge():
    gt = ground_truth([(1, 1, [0, 0, 1, 1], 1), (2, 1, [0, 0, 1, 1], 1)])
    det = detections([(1, [0, 0, 2, 1]), (2, [0, 0, 2.001, 1])])  # IoU exactly 0.5, then just below
    assert match_identities(det, gt).tolist() == [0, -1]
    assert match_identities(det, gt, iou_threshold=0.4).tolist() == [0, 1]
    assert match_identities(det, gt, iou_threshold=0.6).tolist() == [-1, -1]
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="iou_threshold=.* allowed 0 < iou_threshold <= 1"):
            match_identities(det, gt, iou_threshold=bad)


def test_flag_zero_rows_are_neither_matched_nor_scored():
    det = detections([(1, G1), (2, G1)])
    gt = ground_truth([(1, 7, G1, 0), (1, 1, D1, 1), (2, 7, G1, 0)])
    assert match_identities(det, gt).tolist() == [-1, 0, -1]  # the identical flag-0 box is not taken
    assert match_identities(detections([]), gt).tolist() == [-1, -1, -1]


# --- episodes ---------------------------------------------------------------------------------------------------
BOX = [100.0, 50.0, 20.0, 40.0]


def shifted(frame: int) -> list[float]:
    return [BOX[0] + frame, *BOX[1:]]


@pytest.fixture
def small_root(tmp_path: Path) -> Path:
    """Seq-1 (10 fps, 12 frames): identity 1 at frames 2-6 and 9-10 (frame 7 flag 0, frame 8 occluded), detected
    at 2, 3, 5, 7 (on the flag-0 box), 9, 10; identity 2 at frames 1-3; identity 3 only flag 0.
    Other-2 (30 fps): identity 5 at frames 1-4, detected at every frame."""
    gt1 = [line(f, 1, shifted(f), 1) for f in (2, 3, 4, 5, 6, 9, 10)] + [line(7, 1, shifted(7), 0)]
    gt1 += [line(f, 2, [400, 300, 30, 60], 1) for f in (1, 2, 3)] + [line(f, 3, [0, 0, 5, 5], 0) for f in (4, 5)]
    det1 = [line(f, -1, shifted(f), f / 10) for f in (2, 3, 5, 7, 9, 10)] + [line(4, -1, [0, 0, 5, 5], 9.0)]
    det2, gt2 = [line(f, -1, BOX, 2.0) for f in (1, 2, 3, 4)], [line(f, 5, BOX, 1) for f in (1, 2, 3, 4)]
    return make_root(tmp_path, {"Seq-1": (10, 12, det1, gt1), "Other-2": (30, 4, det2, gt2)})


def test_identity_with_gaps(small_root):
    seq1 = load_identities(small_root, ["Seq-1"], min_frames=4, min_detections=3)
    summary = [(i.sequence, i.identity, i.first_frame, i.n_frames, i.n_detections) for i in seq1]
    assert summary == [("Seq-1", 1, 2, 9, 5)]
    ident = seq1[0]
    frames = np.arange(2, 11)
    gap = np.isin(frames, (7, 8))
    assert np.isnan(ident.truth[gap]).all() and ident.tau == pytest.approx(0.1)
    np.testing.assert_array_equal(ident.truth[~gap], [shifted(f) for f in frames[~gap]])
    detected = np.isin(frames, (2, 3, 5, 9, 10))
    np.testing.assert_array_equal(ident.measured[detected], [shifted(f) for f in frames[detected]])
    assert np.isnan(ident.measured[~detected]).all() and np.isnan(ident.scores[~detected]).all()
    np.testing.assert_allclose(ident.scores[detected], frames[detected] / 10)
    track = ident.track()
    np.testing.assert_allclose(track.truth[0], xywh_to_cxcywh(shifted(2)))
    np.testing.assert_allclose(track.y[0], [112, 70, 20, 40])
    assert track.tau == ident.tau and np.isnan(track.y[2]).all()


def test_filters_order_and_errors(small_root):
    all_ids = load_identities(small_root, min_frames=3, min_detections=3)
    assert [(i.sequence, i.identity) for i in all_ids] == [("Other-2", 5), ("Seq-1", 1)]  # sorted; id 2: no det
    assert all_ids[0].tau == pytest.approx(1 / 30)
    assert load_identities(small_root, min_frames=10, min_detections=0) == []
    assert len(load_identities(small_root, min_frames=1, min_detections=5)) == 1
    with pytest.raises(ValueError, match=r"unknown sequence\(s\) \['Nope'\]"):
        load_identities(small_root, ["Nope"])
    with pytest.raises(ValueError, match="min_frames=0"):
        load_identities(small_root, min_frames=0)
    with open(small_root / "Seq-1" / "gt" / "gt.txt", "a") as file:
        file.write(line(13, 1, BOX, 1) + "\n")  # line 14, past the 12 frames of sequences.csv
    with pytest.raises(ValueError, match=r"Seq-1/gt/gt.txt:14: frame 13 is past the sequence's last frame 12"):
        load_identities(small_root)


def test_split_uses_the_otb_rule_by_video():
    items = [MOTIdentity(name, 1, 1, np.ones((2, 4)), np.ones((2, 4)), np.ones(2), 0.1)
             for name in ("ADL-Rundle-6", "ADL-Rundle-8", "ETH-Bahnhof", "ETH-Pedcross2", "KITTI-13", "Venice-2")]
    parts = {k: [i.sequence for i in v] for k, v in split(items).items()}
    assert parts == {"train": ["ETH-Pedcross2", "Venice-2"], "val": ["ADL-Rundle-6", "ADL-Rundle-8", "ETH-Bahnhof"],
                     "test": ["KITTI-13"]}


def test_holdout_split_is_one_leave_one_sequence_out_fold():
    items = [MOTIdentity(name, k, 1, np.ones((2, 4)), np.ones((2, 4)), np.ones(2), 0.1)
             for name in ("ADL-Rundle-6", "KITTI-13", "Venice-2") for k in (1, 2)]
    parts = {k: [(i.sequence, i.identity) for i in v] for k, v in holdout_split(items, "Venice-2").items()}
    assert parts["test"] == [("Venice-2", 1), ("Venice-2", 2)]
    assert parts["train"] == parts["val"] == [("ADL-Rundle-6", 1), ("ADL-Rundle-6", 2), ("KITTI-13", 1), ("KITTI-13", 2)]
    with pytest.raises(ValueError, match=r"mot_holdout='Venice-3' is not a sequence of the MOT data; allowed: "
                                         r"\['ADL-Rundle-6', 'KITTI-13', 'Venice-2'\]"):
        holdout_split(items, "Venice-3")


# --- detection statistics ---------------------------------------------------------------------------------------
def test_detection_stats_on_a_hand_made_identity():
    truth = np.tile([0.0, 0.0, 10.0, 20.0], (10, 1))  # h = 20
    truth[7] = np.nan  # no ground truth at frame 7: not in the miss rate's denominator
    measured = np.full((10, 4), np.nan)
    cx_error = {0: 2.0, 1: 2.0, 2: -2.0, 5: -2.0, 9: 2.0}  # ± 0.1 h: mean 0.2/5 h, std ~0.098 h
    for n, e in cx_error.items():
        measured[n] = truth[n] + [e, 0, 0, 0]
    ident = MOTIdentity("S", 1, 1, truth, measured, np.where(np.isnan(measured[:, 0]), np.nan, 1.0), 0.1)
    stats = detection_stats([ident])
    rel = np.array(list(cx_error.values())) / 20
    assert stats.n_identities == 1 and stats.n_matched == 5 and stats.n_lag_pairs == 2
    np.testing.assert_allclose(stats.error_mean_rel, [rel.mean(), 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(stats.error_std_rel, [rel.std(), 0, 0, 0], atol=1e-15)
    assert stats.miss_rate.tolist() == [pytest.approx(1 - 5 / 9)]
    assert stats.miss_runs.tolist() == [2, 3] and stats.track_length.tolist() == [10]
    summary = stats.summary()
    assert summary["miss_run_median"] == 2.5 and summary["miss_run_max"] == 3 and summary["track_length_median"] == 10
    with pytest.raises(ValueError, match="no identities"):
        detection_stats([])


def test_detection_stats_error_scaling_and_lag_correlation():
    """Errors proportional to the height with AR(1) ψ = 0.8: std, |error|-height correlation and ψ come back."""
    rng = np.random.default_rng(0)
    items, rel = [], []
    for k, height in enumerate(np.linspace(40, 200, 30)):
        u = np.zeros((300, 4))
        for n in range(1, 300):
            u[n] = 0.8 * u[n - 1] + rng.normal(0, 0.03, 4)
        truth = np.tile([100.0, 100.0, height / 2, height], (300, 1))  # cx, cy, w, h
        measured = truth + np.array([height / 2, height, height / 2, height]) * u
        items.append(MOTIdentity("S", k, 1, cxcywh_to_xywh(truth), cxcywh_to_xywh(measured), np.ones(300), 0.1))
        rel.append(u * [0.5, 1, 0.5, 1])
    stats = detection_stats(items)
    np.testing.assert_allclose(stats.lag1_corr, 0.8, atol=0.03)
    np.testing.assert_allclose(stats.error_std_rel, np.concatenate(rel).std(axis=0), rtol=1e-9)
    assert (stats.abs_error_height_corr > 0.3).all() and stats.miss_runs.size == 0 and stats.miss_rate.max() == 0


# --- the real MOT15 copy (MOT_ROOT) -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def mot15(mot_root: Path) -> list[MOTIdentity]:
    return load_identities(mot_root)


def test_identity_counts_per_sequence_and_split_part(mot15):
    counts = {}
    for ident in mot15:
        counts[ident.sequence] = counts.get(ident.sequence, 0) + 1
    assert counts == {"ADL-Rundle-6": 23, "ADL-Rundle-8": 24, "ETH-Bahnhof": 87, "ETH-Pedcross2": 27, "KITTI-13": 15,
                      "Venice-2": 24}
    assert [(i.sequence, i.identity) for i in mot15] == sorted((i.sequence, i.identity) for i in mot15)
    parts = split(mot15)
    assert {k: len(v) for k, v in parts.items()} == {"train": 51, "val": 134, "test": 15}
    assert {i.sequence for i in parts["train"]} == {"ETH-Pedcross2", "Venice-2"}


def test_every_matched_detection_overlaps_its_truth(mot15):
    for ident in mot15:
        detected = np.isfinite(ident.scores)
        assert ident.n_frames >= MIN_FRAMES and detected.sum() >= MIN_DETECTIONS
        assert np.isfinite(ident.truth[0]).all() and np.isfinite(ident.truth[-1]).all()
        assert (iou(ident.measured[detected], ident.truth[detected]) >= MATCH_IOU).all(), ident.identity
        assert np.isnan(ident.measured[~detected]).all()
    assert {round(1 / i.tau) for i in mot15} == {10, 14, 30}


def test_matching_equals_a_frame_by_frame_reference(mot_root):
    """The vectorised pair construction against the plain per-frame loop, on a sequence with flag-0 rows."""
    det = read_detections(mot_root / "ETH-Bahnhof" / "det" / "det.txt")
    gt = read_ground_truth(mot_root / "ETH-Bahnhof" / "gt" / "gt.txt")
    expected = np.full(len(gt), -1)
    for frame in np.unique(gt.frame):
        d, g = np.flatnonzero(det.frame == frame), np.flatnonzero((gt.frame == frame) & gt.flag)
        overlap = iou(det.box[d][:, None], gt.box[g][None])
        overlap[overlap < 0.5] = 0
        rows, cols = linear_sum_assignment(overlap, maximize=True)
        keep = overlap[rows, cols] >= 0.5
        expected[g[cols[keep]]] = d[rows[keep]]
    got = match_identities(det, gt)
    np.testing.assert_array_equal(got, expected)
    assert (got[~gt.flag] == -1).all() and len(set(got[got >= 0].tolist())) == int((got >= 0).sum())


def test_statistics_of_the_data(mot15):
    summary = detection_stats(mot15).summary()
    assert summary["identities"] == 200 and 0.02 < summary["error_std_rel_cx"] < 0.1
    assert 0.3 < summary["lag1_corr_cx"] < 0.9 and 0 < summary["miss_rate_mean"] < 0.6
