"""MOT15 identity episodes: public detections matched to ground-truth identities, the split, and the detection
noise statistics a simulator needs.

Data (``$MOT_ROOT``, CI: ``../shared/data/mot15``): ``sequences.csv`` and ``<seq>/det/det.txt``,
``<seq>/gt/gt.txt`` in the MOT15 layout read by :mod:`bboxtune.envs.data.mot_io`. Conventions, as the benchmark scores a
detection stream (``shared/notes/mot-baselines.md``):

* **Boxes** are xywh in pixels ((x, y) top-left, continuous areas, :mod:`bboxtune.envs.data.boxes`). The filters'
  (cx, cy, w, h) come from :meth:`MOTIdentity.track` (or ``bboxtune.envs.data.boxes.xywh_to_cxcywh``).
* **Invalid ground truth**: rows with flag 0 are ignored, neither matched nor scored nor part of an identity.
* **Matching** (:func:`match_identities`): per frame, the Hungarian assignment maximising the summed IoU between
  the frame's detections and its counted ground-truth boxes, over pairs with IoU >= :data:`MATCH_IOU` (pairs
  below it are not allowed, as in the MOT devkit; IoU exactly 0.5 is kept).
* **Episodes** (:class:`MOTIdentity`): an identity from its first to its last counted ground-truth frame (the
  first frame is the 1-based frame number of row 0); frames in between without a counted row (occlusion, flag
  0) are NaN truth rows; the measurement is the detection matched to the identity in that frame, else NaN.
  τ = 1 / fps of ``sequences.csv``. :func:`load_identities` keeps identities with >= :data:`MIN_FRAMES` frames
  (gaps included) and >= :data:`MIN_DETECTIONS` matched detections.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from bboxtune.envs.data import otb, textfile
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.envs.data.metrics import iou
from bboxtune.envs.data.mot_io import Detections, GroundTruth, read_detections, read_ground_truth, read_sequences_csv
from bboxtune.envs.data.simulate import Track

MOT_ROOT_ENV = "MOT_ROOT"
MATCH_IOU = 0.5  # the MOT benchmark's detection-to-ground-truth threshold
MIN_FRAMES = 20  # shortest identity episode kept (frames from first to last counted ground truth)
MIN_DETECTIONS = 10  # fewest matched detections an identity episode needs
COORDINATES = ("cx", "cy", "w", "h")


@dataclass(frozen=True, eq=False)
class MOTIdentity:
    """One ground-truth identity of a sequence as an episode (see the module docstring)."""

    sequence: str  # e.g. "ADL-Rundle-6"
    identity: int  # the gt.txt id
    first_frame: int  # 1-based frame of row 0 (the identity's first counted ground truth)
    truth: np.ndarray  # (T, 4) xywh px; NaN rows: no counted ground truth in that frame
    measured: np.ndarray  # (T, 4) xywh px of the matched public detection; NaN rows: none matched
    scores: np.ndarray  # (T,) the matched detection's score, NaN where none
    tau: float  # s, 1 / fps

    @property
    def n_frames(self) -> int:
        """Episode length T (frames from the first to the last counted ground truth)."""
        return len(self.truth)

    @property
    def n_detections(self) -> int:
        """Frames with a matched detection."""
        return int(np.isfinite(self.scores).sum())

    def track(self) -> Track:
        """The episode as a :class:`bboxtune.envs.data.simulate.Track` in (cx, cy, w, h) px (``otb.replay_tracker``)."""
        return otb.replay_tracker(self.truth, self.measured, tau=self.tau)


def resolve_root(root: str | os.PathLike | None) -> Path:
    """``root`` if given, else ``$MOT_ROOT``; ValueError when neither names an existing path."""
    return textfile.data_root(root, MOT_ROOT_ENV, "MOT")


def _check_threshold(iou_threshold: float) -> float:
    if not (np.isfinite(iou_threshold) and 0 < iou_threshold <= 1):
        raise ValueError(f"iou_threshold={iou_threshold!r} is out of range: allowed 0 < iou_threshold <= 1")
    return float(iou_threshold)


def match_identities(det: Detections, gt: GroundTruth, iou_threshold: float = MATCH_IOU) -> np.ndarray:
    """(N_gt,) int64: for each ground-truth row, the row of the detection matched to it, or -1.

    Per frame, the Hungarian assignment (``scipy.optimize.linear_sum_assignment``) maximises the summed IoU over
    pairs of the frame's detections and counted (flag 1) ground-truth boxes with IoU >= ``iou_threshold``;
    flag-0 rows always get -1. Each detection and each ground-truth row is matched at most once."""
    threshold = _check_threshold(iou_threshold)
    counted = np.flatnonzero(gt.flag)
    g_order = counted[np.argsort(gt.frame[counted], kind="stable")]
    d_order = np.argsort(det.frame, kind="stable")
    g_frames, d_frames = gt.frame[g_order], det.frame[d_order]
    frames = np.intersect1d(g_frames, d_frames)
    g_lo, g_hi = np.searchsorted(g_frames, frames), np.searchsorted(g_frames, frames, side="right")
    d_lo, d_hi = np.searchsorted(d_frames, frames), np.searchsorted(d_frames, frames, side="right")
    # every frame's (detections × ground truth) IoU matrix, row-major, in one vectorised call
    n_det, n_gt = d_hi - d_lo, g_hi - g_lo
    sizes = n_det * n_gt
    starts = np.cumsum(sizes) - sizes
    offset = np.arange(sizes.sum()) - np.repeat(starts, sizes)
    width = np.repeat(n_gt, sizes)
    d_pair = d_order[np.repeat(d_lo, sizes) + offset // width]
    g_pair = g_order[np.repeat(g_lo, sizes) + offset % width]
    overlaps = iou(det.box[d_pair], gt.box[g_pair])
    allowed = np.where(overlaps >= threshold, overlaps, 0.0)  # a zero pair adds nothing: dropped below
    candidates: np.ndarray | list[int] = np.flatnonzero(np.add.reduceat(allowed, starts) > 0) if len(frames) else []
    out = np.full(len(gt), -1, dtype=np.int64)
    for k in candidates:  # the frames with at least one allowed pair
        matrix = allowed[starts[k]:starts[k] + sizes[k]].reshape(n_det[k], n_gt[k])
        rows, cols = linear_sum_assignment(matrix, maximize=True)
        keep = matrix[rows, cols] >= threshold
        out[g_order[g_lo[k] + cols[keep]]] = d_order[d_lo[k] + rows[keep]]
    return out


def _identities(name: str, det: Detections, gt: GroundTruth, det_of_gt: np.ndarray, tau: float,
                min_frames: int, min_detections: int) -> list[MOTIdentity]:
    counted = np.flatnonzero(gt.flag)
    order = counted[np.lexsort((gt.frame[counted], gt.id[counted]))]
    ids = gt.id[order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]]) if len(order) else np.empty(0, dtype=np.int64)
    out = []
    for start, end in zip(starts, np.r_[starts[1:], len(order)], strict=True):
        rows = order[start:end]
        frames, matched = gt.frame[rows], det_of_gt[rows]
        first, n_frames, hit = int(frames[0]), int(frames[-1] - frames[0] + 1), matched >= 0
        if n_frames < min_frames or hit.sum() < min_detections:
            continue
        truth, measured = np.full((n_frames, 4), np.nan), np.full((n_frames, 4), np.nan)
        scores = np.full(n_frames, np.nan)
        truth[frames - first] = gt.box[rows]
        measured[frames[hit] - first] = det.box[matched[hit]]
        scores[frames[hit] - first] = det.score[matched[hit]]
        out.append(MOTIdentity(sequence=name, identity=int(ids[start]), first_frame=first, truth=truth,
                               measured=measured, scores=scores, tau=tau))
    return out


def _check_frames(path: Path, frame: np.ndarray, n_frames: int) -> None:
    late = frame > n_frames
    if late.any():
        i = int(np.argmax(late))
        raise ValueError(f"{path}:{i + 1}: frame {frame[i]} is past the sequence's last frame {n_frames} "
                         f"(sequences.csv); allowed 1 <= frame <= {n_frames}")


def load_identities(root: str | os.PathLike | None = None, sequences: Iterable[str] | None = None, *,
                    min_frames: int = MIN_FRAMES, min_detections: int = MIN_DETECTIONS,
                    iou_threshold: float = MATCH_IOU) -> list[MOTIdentity]:
    """Identity episodes of ``sequences`` (default: every row of ``sequences.csv``) under ``root``
    (default ``$MOT_ROOT``), sorted by sequence name, then identity id.

    Keeps identities with >= ``min_frames`` frames and >= ``min_detections`` matched detections. A detection or
    ground-truth frame past the sequence's ``frames`` in ``sequences.csv`` is a ValueError naming the line.
    Nothing is cached: the whole MOT15 copy (six sequences) loads in about half a second."""
    base = resolve_root(root)
    if min_frames < 1 or min_detections < 0:
        raise ValueError(f"min_frames={min_frames}, min_detections={min_detections}; allowed >= 1 and >= 0")
    threshold = _check_threshold(iou_threshold)
    table = read_sequences_csv(base)
    names = sorted(table if sequences is None else set(sequences))
    unknown = [n for n in names if n not in table]
    if unknown:
        raise ValueError(f"unknown sequence(s) {unknown}; {base / 'sequences.csv'} lists {list(table)}")
    out: list[MOTIdentity] = []
    for name in names:
        det_path, gt_path = base / name / "det" / "det.txt", base / name / "gt" / "gt.txt"
        det, gt = read_detections(det_path), read_ground_truth(gt_path)
        _check_frames(det_path, det.frame, table[name].frames)
        _check_frames(gt_path, gt.frame, table[name].frames)
        out += _identities(name, det, gt, match_identities(det, gt, threshold), 1.0 / table[name].fps,
                           min_frames, min_detections)
    return out


def split(identities: Iterable[MOTIdentity]) -> dict[str, tuple[MOTIdentity, ...]]:
    """Identities by train / val / test part of their sequence, with the OTB rule :func:`bboxtune.envs.data.otb.split`.

    The rule hashes the sequence's video name (``otb.video_of``: ``ADL-Rundle-6`` and ``ADL-Rundle-8`` are the
    video ``ADL-Rundle`` and share a part). On the six MOT15 sequences of ``shared/data/mot15``: train =
    ETH-Pedcross2, Venice-2 (27 + 24 = 51 identities with the defaults of :func:`load_identities`);
    val = ADL-Rundle-6, ADL-Rundle-8, ETH-Bahnhof (23 + 24 + 87 = 134); test = KITTI-13 (15). For the sequence
    names themselves call ``otb.split(names)``."""
    items = tuple(identities)
    part_of = {name: part for part, names in otb.split({i.sequence for i in items}).items() for name in names}
    return {part: tuple(i for i in items if part_of[i.sequence] == part) for part in ("train", "val", "test")}


def holdout_split(identities: Iterable[MOTIdentity], holdout: str) -> dict[str, tuple[MOTIdentity, ...]]:
    """One leave-one-sequence-out fold: "test" = the identities of sequence ``holdout``, "train" and "val" = those of
    every other sequence (the fold's val part is its training sequences: there is no third part to select on).
    ValueError naming the sequences if ``holdout`` is none of them."""
    items = tuple(identities)
    names = sorted({i.sequence for i in items})
    if holdout not in names:
        raise ValueError(f"mot_holdout={holdout!r} is not a sequence of the MOT data; allowed: {names}")
    others = tuple(i for i in items if i.sequence != holdout)
    return {"train": others, "val": others, "test": tuple(i for i in items if i.sequence == holdout)}


@dataclass(frozen=True, eq=False)
class DetectionStats:
    """Detection noise of identity episodes, measured on matched frames (see :func:`detection_stats`).

    Coordinate axes are (cx, cy, w, h) (:data:`COORDINATES`); errors are detection minus truth."""

    n_identities: int
    n_matched: int  # frames with a matched detection, all identities
    error_mean_rel: np.ndarray  # (4,) mean error / true height
    error_std_rel: np.ndarray  # (4,) std of error / true height
    abs_error_height_corr: np.ndarray  # (4,) Pearson correlation of |error| (px) with the true height
    lag1_corr: np.ndarray  # (4,) lag-1 correlation of error / height over consecutive detected frames (ψ)
    n_lag_pairs: int  # pairs of consecutive detected frames behind lag1_corr
    miss_rate: np.ndarray  # (n_identities,) frames with counted truth but no detection / frames with truth
    miss_runs: np.ndarray  # lengths of the runs of frames without detection between first and last detection
    track_length: np.ndarray  # (n_identities,) episode lengths T

    def summary(self) -> dict[str, float]:
        """Flat numbers for a docs table (quartiles are q25, median, q75)."""
        out: dict[str, float] = {"identities": self.n_identities, "matched": self.n_matched,
                                 "lag_pairs": self.n_lag_pairs}
        for k, c in enumerate(COORDINATES):
            out |= {f"error_mean_rel_{c}": float(self.error_mean_rel[k]),
                    f"error_std_rel_{c}": float(self.error_std_rel[k]),
                    f"abs_error_height_corr_{c}": float(self.abs_error_height_corr[k]),
                    f"lag1_corr_{c}": float(self.lag1_corr[k])}
        q25, q50, q75 = np.quantile(self.miss_rate, [0.25, 0.5, 0.75])
        out |= {"miss_rate_mean": float(self.miss_rate.mean()), "miss_rate_q25": float(q25),
                "miss_rate_median": float(q50), "miss_rate_q75": float(q75), "miss_runs": len(self.miss_runs),
                "miss_run_median": float(np.median(self.miss_runs)) if len(self.miss_runs) else float("nan"),
                "miss_run_max": float(self.miss_runs.max()) if len(self.miss_runs) else float("nan"),
                "track_length_median": float(np.median(self.track_length)),
                "track_length_q25": float(np.quantile(self.track_length, 0.25)),
                "track_length_q75": float(np.quantile(self.track_length, 0.75))}
        return out


def _correlation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pearson correlation of the columns of two (N, 4) arrays; NaN for a column without variance."""
    a, b = a - a.mean(axis=0), b - b.mean(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (a * b).sum(axis=0) / np.sqrt((a * a).sum(axis=0) * (b * b).sum(axis=0))


def detection_stats(identities: Iterable[MOTIdentity]) -> DetectionStats:
    """Detection error, its scaling with the box height, its lag-1 correlation, misses and episode lengths.

    Errors are (cx, cy, w, h) of the detection minus those of the truth on frames with both; relative errors
    divide by the true height h. ``lag1_corr`` pools the pairs (u_n, u_{n+1}) of relative errors of all
    identities where frames n and n + 1 are both detected (an estimate of the Gauss–Markov ψ per frame). A
    miss run is a maximal run of frames without detection strictly between an identity's first and last
    detection (frames without ground truth included)."""
    items = tuple(identities)
    if not items:
        raise ValueError("no identities: detection_stats needs at least one")
    errors, heights, lag_a, lag_b, miss_rate, runs = [], [], [], [], [], []
    for ident in items:
        truth, measured = xywh_to_cxcywh(ident.truth), xywh_to_cxcywh(ident.measured)
        rel = (measured - truth) / truth[:, 3:]
        both = np.isfinite(rel).all(axis=1)
        errors.append((measured - truth)[both])
        heights.append(truth[both, 3])
        pairs = both[:-1] & both[1:]
        lag_a.append(rel[:-1][pairs])
        lag_b.append(rel[1:][pairs])
        has_truth = np.isfinite(truth).all(axis=1)
        miss_rate.append(1.0 - both.sum() / has_truth.sum())
        gaps = np.diff(np.flatnonzero(np.isfinite(measured).all(axis=1))) - 1
        runs.append(gaps[gaps > 0])
    error, height = np.concatenate(errors), np.concatenate(heights)
    rel = error / height[:, None]
    return DetectionStats(
        n_identities=len(items), n_matched=len(error), error_mean_rel=rel.mean(axis=0),
        error_std_rel=rel.std(axis=0),
        abs_error_height_corr=_correlation(np.abs(error), np.repeat(height[:, None], 4, axis=1)),
        lag1_corr=_correlation(np.concatenate(lag_a), np.concatenate(lag_b)), n_lag_pairs=sum(map(len, lag_a)),
        miss_rate=np.array(miss_rate), miss_runs=np.concatenate(runs),
        track_length=np.array([i.n_frames for i in items]))
