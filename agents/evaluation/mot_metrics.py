"""CLEAR MOT and identity scores of a tracker's MOT15 output, computed by motmetrics (py-motmetrics).

Every number here is motmetrics' own (:class:`motmetrics.MOTAccumulator` and ``motmetrics.metrics.create()``);
this module only reads the files and feeds the accumulator, frame by frame, as motmetrics' MOT Challenge
evaluator (``motmetrics/apps/eval_motchallenge.py``, ``motmetrics.utils.compare_to_groundtruth``) does:

* **Files**: ground truth ``<SEQ>/gt/gt.txt`` and results ``<SEQ>.txt`` through the strict readers of
  :mod:`bboxtune.envs.data.mot_io` (``read_ground_truth``, ``read_results``: ``file:line`` errors for a malformed
  row, a repeated (frame, id) pair, a zero-size box).
* **Flag-0 ground truth is dropped** before scoring, as motmetrics' MOT15 path does (it loads ground truth with
  ``min_confidence=1``, so rows with flag 0 never reach the accumulator) and as TrackEval does for MOT15 (which
  removes the zero-marked rows and, for MOT15 only, does not remove the tracker boxes matched to them). So a
  flag-0 row is neither a miss nor a match, an identity with only flag-0 rows is not counted, and a tracker box
  on a flag-0 pedestrian is a false positive. (The MOT16+ distractor step, ``motmetrics.preprocess``, needs the
  class column that MOT15 lacks.) The results' score column is not used: every results row is a hypothesis
  (motmetrics' loader keeps rows with score >= -1; MOT trackers write 1 or -1).
* **Frames**: every frame that has a counted ground-truth row or a results row, in increasing order; a results
  row in a frame without ground truth is a false positive.
* **Matching distance**: 1 − IoU of xywh boxes, pairs with IoU < 0.5 not allowed (NaN), the MOT threshold
  (``compare_to_groundtruth(..., 'iou', distth=0.5)``). :func:`iou_distance` computes it with
  :func:`bboxtune.envs.data.metrics.iou` instead of ``motmetrics.distances.iou_matrix``, **because that function
  calls** ``np.asfarray`` (``motmetrics/distances.py`` line 117), **which NumPy 2 removed**: motmetrics 1.4.0, its
  latest release, fails on NumPy 2 there (fixed upstream by py-motmetrics PR #200, not released). This is the one
  place that works around it; no motmetrics code that calls ``np.asfarray`` runs here, and NumPy is not patched.
  ``tests/agents/evaluation/test_mot_metrics.py`` pins the semantics: :func:`iou_distance` equals motmetrics'
  ``iou_matrix`` (run under a scoped ``np.asfarray`` shim that the test removes again). Once a fixed motmetrics
  is released, ``iou_matrix`` can replace :func:`iou_distance`.

Scores (:data:`COLUMNS`, motmetrics' names): ``mota``, ``motp`` (motmetrics' MOTP: the mean distance 1 − IoU of
the matches, lower is better; the MOT Challenge tables print 1 − it), ``idf1``, ``idp``, ``idr``,
``num_switches``, ``switches_per_identity`` (``num_switches / num_unique_objects``, the ID switches per
ground-truth identity; NaN without identities; the one column computed here, from motmetrics' two counts),
``mostly_tracked``, ``mostly_lost``, ``num_false_positives``, ``num_misses``, ``num_objects`` (counted
ground-truth boxes), ``num_unique_objects`` (identities). Per sequence and an overall row
(``compute_many(..., generate_overall=True)``: the counts summed, the ratios recomputed from the sums).

HOTA is not computed: motmetrics 1.4.0 has no HOTA. The reference implementation is TrackEval; the PyPI package
``trackeval`` (1.3.0) is a fork's packaging of it that requires ``opencv-python`` (which clashes with this
project's ``opencv-python-headless``: both install ``cv2``) and ``pycocotools``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import motmetrics as mm
import numpy as np
from numpy.typing import ArrayLike

from bboxtune.envs.data.metrics import iou
from bboxtune.envs.data.mot_io import GroundTruth, Results, read_ground_truth, read_results

MOT_IOU = 0.5  # a match needs IoU >= 0.5 (distance 1 - IoU <= 0.5)
OVERALL = "OVERALL"  # motmetrics' name of the overall row
METRICS = ("mota", "motp", "idf1", "idp", "idr", "num_switches", "mostly_tracked", "mostly_lost",
           "num_false_positives", "num_misses", "num_objects", "num_unique_objects")
SWITCHES_PER_IDENTITY = "switches_per_identity"
COLUMNS = (*METRICS[:6], SWITCHES_PER_IDENTITY, *METRICS[6:])
COUNTS = frozenset(c for c in METRICS if c.startswith(("num_", "mostly_")))  # integers; the rest are ratios

Scores = dict[str, float | int]


def _box_rows(name: str, boxes: ArrayLike) -> np.ndarray:
    """``boxes`` as an (N, 4) float array; ValueError naming ``name`` otherwise."""
    try:
        arr = np.asarray(boxes, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} is not an array of numbers ({err})") from None
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise ValueError(f"{name} has shape {arr.shape}; allowed: (N, 4) xywh boxes")
    return arr


def iou_distance(gt_boxes: ArrayLike, hyp_boxes: ArrayLike, min_iou: float = MOT_IOU) -> np.ndarray:
    """(N, K) matching distances 1 − IoU between N ground-truth and K hypothesis xywh boxes; NaN (do not pair)
    where IoU < ``min_iou``. Equals ``motmetrics.distances.iou_matrix(gt, hyp, max_iou=1 - min_iou)`` for
    non-empty inputs (module docstring: why that function is not called).

    >>> iou_distance(np.array([[0.0, 0, 2, 2]]), np.array([[0.0, 0, 2, 1], [1.0, 0, 2, 2]])).tolist()
    [[0.5, nan]]
    """
    gt, hyp = _box_rows("gt_boxes", gt_boxes), _box_rows("hyp_boxes", hyp_boxes)
    dist = 1.0 - iou(gt[:, None, :], hyp[None, :, :])
    return np.where(dist > 1.0 - min_iou, np.nan, dist)


def _rows_by_frame(frame: np.ndarray) -> dict[int, np.ndarray]:
    """Frame number → the row indices in that frame (in file order)."""
    if not len(frame):
        return {}
    order = np.argsort(frame, kind="stable")
    frames, starts = np.unique(frame[order], return_index=True)
    return dict(zip(frames.tolist(), np.split(order, starts[1:]), strict=True))


def accumulate(gt: GroundTruth, results: Results) -> mm.MOTAccumulator:
    """motmetrics' accumulator of one sequence: flag-0 ground truth dropped, every results row a hypothesis,
    one ``update`` per frame with :func:`iou_distance` (module docstring)."""
    counted = gt.flag
    gt_frame, gt_id, gt_box = gt.frame[counted], gt.id[counted], gt.box[counted]
    gt_rows, hyp_rows = _rows_by_frame(gt_frame), _rows_by_frame(results.frame)
    empty = np.empty(0, dtype=np.int64)
    acc = mm.MOTAccumulator(auto_id=False)
    for frame in sorted(gt_rows.keys() | hyp_rows.keys()):
        g, h = gt_rows.get(frame, empty), hyp_rows.get(frame, empty)
        acc.update(gt_id[g].tolist(), results.id[h].tolist(), iou_distance(gt_box[g], results.box[h]), frameid=frame)
    return acc


def _scores(row: Any) -> Scores:
    """One row of motmetrics' summary (a pandas Series) as :data:`COLUMNS`, with the switches per identity."""
    out: Scores = {name: int(row[name]) if name in COUNTS else float(row[name]) for name in METRICS}
    identities = out["num_unique_objects"]
    out[SWITCHES_PER_IDENTITY] = out["num_switches"] / identities if identities else float("nan")
    return {name: out[name] for name in COLUMNS}


def score(accumulators: Mapping[str, mm.MOTAccumulator]) -> dict[str, Scores]:
    """:data:`COLUMNS` of each sequence (name → accumulator, in the given order), then of :data:`OVERALL`."""
    if not accumulators:
        raise ValueError("accumulators: no sequences to score")
    if OVERALL in accumulators:
        raise ValueError(f"accumulators: {OVERALL!r} is the overall row's name; rename that sequence")
    table = mm.metrics.create().compute_many(list(accumulators.values()), metrics=list(METRICS),
                                             names=list(accumulators), generate_overall=True)
    return {str(name): _scores(row) for name, row in table.iterrows()}


def score_files(files: Mapping[str, tuple[str | os.PathLike, str | os.PathLike]]) -> dict[str, Scores]:
    """:func:`score` of sequences given as name → (``gt.txt``, results file); every file is read (ValueError
    naming ``file:line`` for a malformed one) before anything is scored."""
    pairs = {name: (read_ground_truth(gt), read_results(res)) for name, (gt, res) in files.items()}
    return score({name: accumulate(gt, res) for name, (gt, res) in pairs.items()})


def ground_truth_files(root: str | os.PathLike) -> dict[str, Path]:
    """Sequence name → ``<root>/<SEQ>/gt/gt.txt`` for every sub-folder of ``root`` that has one, sorted by name."""
    return {p.parent.parent.name: p for p in sorted(Path(root).glob("*/gt/gt.txt")) if p.is_file()}


def results_files(folder: str | os.PathLike) -> dict[str, Path]:
    """Sequence name → ``<folder>/<SEQ>.txt`` for every ``.txt`` file directly in ``folder``, sorted by name."""
    return {p.stem: p for p in sorted(Path(folder).glob("*.txt")) if p.is_file()}


def format_value(name: str, value: float | int) -> str:
    """A score as the table prints it: counts as integers, ratios with 3 decimals."""
    return str(value) if name in COUNTS else f"{value:.3f}"


def markdown_table(scores: Mapping[str, Scores]) -> str:
    """The scores as a markdown table, one row per sequence (the overall row last, as :func:`score` orders it)."""
    lines = ["| sequence | " + " | ".join(COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    lines += [f"| {name} | " + " | ".join(format_value(c, row[c]) for c in COLUMNS) + " |" for name, row in scores.items()]
    return "\n".join(lines) + "\n"
