"""Leave-one-sequence-out (LOSO) evaluation of the tracker's causal prediction search (``--filter search``) against
SORT's and ByteTrack's stock filters in the same SORT-style tracker, on MOT15 public detections.

    python scripts/track_loso.py --mot-root ../shared/data/mot15 --out docs/results/tracking/loso.csv

Every setting of the pre-declared grid :data:`GRID` (window W, history, candidate grid width) tracks every
sequence once, as do ``sort_kf`` and ``bytetrack_kf`` (SORT's settings otherwise). For each fold, the held-out
sequence's setting is the one with the best overall IDF1 on the other sequences (motmetrics' overall IDF1:
2 IDTP / (2 IDTP + IDFP + IDFN) over the summed counts), and the fold reports the held-out sequence's IDF1, MOTA and
ID switches per identity with that setting, and its ΔIDF1 / ΔMOTA against each stock filter. The summary gives
the folds' mean Δ and a bootstrap over sequences (the fold deltas resampled with replacement, ``--boot`` times,
seed ``--seed``): the 95 % interval of the mean and the fraction of resamples with a mean > 0.

Writes ``--out`` (CSV, one row per fold, then a ``mean`` row), the same stem with ``.md`` (the fold table and
the summary) and with ``_runs.csv`` (every run's motmetrics counts per sequence: run ``sort_kf``, ``bytetrack_kf``
or the grid setting's index), atomically; existing files are never overwritten. Bad input: one line, exit
status 2.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import motmetrics as mm
import numpy as np
from tqdm import tqdm

from bboxtune.agents.cli import ArgumentParser, HelpFormatter, command, existing_dir, int_range, new_file
from bboxtune.agents.evaluation import mot_metrics
from bboxtune.agents.evaluation.video_tables import csv_text
from bboxtune.agents.tracking.search_tune import SearchSettings
from bboxtune.agents.tracking.sort_tracker import SEARCH, make_tracker
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.data.mot import resolve_root
from bboxtune.envs.data.mot_io import GroundTruth, Results, read_detections, read_ground_truth, read_sequences_csv

# The pre-declared grid: frames between re-tunes W, the candidate grid's largest scale, the IoU cap of the score
GRID: tuple[SearchSettings, ...] = tuple(SearchSettings(window=w, width=k, cap=c)
                                         for w, k, c in itertools.product((5, 10), (2.0, 4.0), (0.5, 1.0)))
STOCK_FILTERS = ("sort_kf", "bytetrack_kf")
COUNTS = ("idtp", "idfp", "idfn", "num_switches", "num_unique_objects", "mota", "idf1")


@dataclass(frozen=True)
class Sequence:
    """One sequence's detections, ground truth and frame interval."""

    det_frame: np.ndarray
    det_box: np.ndarray
    det_score: np.ndarray
    truth: GroundTruth
    frames: int
    tau: float


def scores(sequence: Sequence, filter_name: str, settings: SearchSettings | None) -> dict[str, float]:
    """:data:`COUNTS` of one tracker run (``filter_name``, the search with ``settings``) on ``sequence``."""
    tracker = make_tracker(filter_name, sequence.tau, search=settings)
    frame, ids, boxes = [], [], []
    for r in tracker.run(sequence.det_frame, sequence.det_box, sequence.det_score, sequence.frames):
        frame += [r.frame] * len(r.ids)
        ids += r.ids.tolist()
        boxes += r.boxes.tolist()
    results = Results(np.array(frame, dtype=np.int64), np.array(ids, dtype=np.int64),
                      np.array(boxes, dtype=float).reshape(-1, 4), np.ones(len(frame)))
    row = mm.metrics.create().compute(mot_metrics.accumulate(sequence.truth, results), metrics=list(COUNTS),
                                      return_dataframe=False)
    return {name: float(row[name]) for name in COUNTS}


def overall_idf1(counts: list[Mapping[str, float]]) -> float:
    """motmetrics' overall IDF1 of several sequences: 2 IDTP / (2 IDTP + IDFP + IDFN) over the summed counts."""
    idtp, idfp, idfn = (sum(c[name] for c in counts) for name in ("idtp", "idfp", "idfn"))
    return 2 * idtp / (2 * idtp + idfp + idfn)


def loso(table: Mapping[str, Mapping[str, dict[str, float]]], grid: int) -> list[dict[str, object]]:
    """The folds: ``table[run][sequence]`` holds :data:`COUNTS`, runs ``"0"`` … ``str(grid − 1)`` (the grid's
    settings) and the stock filters."""
    names = list(table[STOCK_FILTERS[0]])
    folds: list[dict[str, object]] = []
    for held in names:
        others = [name for name in names if name != held]
        best = max(range(grid), key=lambda g: (overall_idf1([table[str(g)][n] for n in others]), -g))
        chosen = table[str(best)][held]
        row: dict[str, object] = {"sequence": held, "setting": best, "idf1": chosen["idf1"], "mota": chosen["mota"],
                                  "switches_per_identity": chosen["num_switches"] / chosen["num_unique_objects"]}
        for stock in STOCK_FILTERS:
            peer = table[stock][held]
            row[f"idf1_{stock}"], row[f"mota_{stock}"] = peer["idf1"], peer["mota"]
            row[f"d_idf1_{stock}"] = chosen["idf1"] - peer["idf1"]
            row[f"d_mota_{stock}"] = chosen["mota"] - peer["mota"]
        folds.append(row)
    return folds


def bootstrap(deltas: np.ndarray, n: int, seed: int) -> tuple[float, float, float]:
    """The 95 % interval of the mean of ``deltas`` over ``n`` resamples with replacement, and the fraction of
    resamples whose mean is > 0."""
    rng = np.random.default_rng(seed)
    means = deltas[rng.integers(0, len(deltas), (n, len(deltas)))].mean(axis=1)
    low, high = np.quantile(means, [0.025, 0.975])
    return float(low), float(high), float((means > 0).mean())


def markdown(folds: list[dict[str, object]], summary: list[str]) -> str:
    """The fold table and the summary lines as markdown."""
    head = ["held out", "setting (W, width, cap)", "IDF1", "ΔIDF1 vs sort_kf", "ΔIDF1 vs bytetrack_kf", "MOTA",
            "ΔMOTA vs sort_kf", "ΔMOTA vs bytetrack_kf", "switches / identity"]
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for f in folds:
        s = GRID[int(str(f["setting"]))]
        lines.append(f"| {f['sequence']} | {s.window}, {s.width:g}, {s.cap:g} | {f['idf1']:.3f} | "
                     f"{f['d_idf1_sort_kf']:+.3f} | {f['d_idf1_bytetrack_kf']:+.3f} | {f['mota']:.3f} | "
                     f"{f['d_mota_sort_kf']:+.3f} | {f['d_mota_bytetrack_kf']:+.3f} | {f['switches_per_identity']:.3f} |")
    return "\n".join(lines) + "\n\n" + "\n".join(f"- {line}" for line in summary) + "\n"


@command
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(prog="track_loso.py", description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("--mot-root", type=existing_dir, default=None, help="MOT15 data folder (default: $MOT_ROOT)")
    p.add_argument("--out", required=True, type=new_file, help="the fold CSV to write (a .md beside it)")
    p.add_argument("--boot", type=int_range(100, 10**6), default=10000, help="bootstrap resamples (default 10000)")
    p.add_argument("--seed", type=int_range(0, 2**31 - 1), default=0, help="bootstrap seed (default 0)")
    args = p.parse_args(argv)
    if args.out.suffix != ".csv":
        p.error(f"--out {args.out}: allowed a .csv file name (the .md beside it is written too)")
    summary_path = args.out.with_suffix(".md")
    runs_path = args.out.with_name(args.out.stem + "_runs.csv")
    for path in (summary_path, runs_path):
        if path.exists():
            p.error(f"--out: {path} exists; allowed: a new file")
    try:
        root = resolve_root(args.mot_root)
        data = {name: Sequence(*_detections(root / name / "det" / "det.txt"),
                               read_ground_truth(root / name / "gt" / "gt.txt"), info.frames, 1.0 / info.fps)
                for name, info in read_sequences_csv(root).items()}
    except (ValueError, OSError) as err:
        p.error(f"--mot-root: {err}")
    runs: list[tuple[str, str, SearchSettings | None]] = [(s, s, None) for s in STOCK_FILTERS]
    runs += [(str(g), SEARCH, settings) for g, settings in enumerate(GRID)]
    table: dict[str, dict[str, dict[str, float]]] = {}
    for key, name, settings in tqdm(runs, unit="run", disable=None):
        table[key] = {seq: scores(sequence, name, settings) for seq, sequence in data.items()}
    folds = loso(table, len(GRID))
    summary = []
    for stock in STOCK_FILTERS:
        for metric in ("idf1", "mota"):
            deltas = np.array([float(str(f[f"d_{metric}_{stock}"])) for f in folds])
            low, high, positive = bootstrap(deltas, args.boot, args.seed)
            summary.append(f"Δ{metric.upper()} vs {stock}: mean {deltas.mean():+.4f} over {len(deltas)} folds "
                           f"({(deltas > 0).sum()} > 0); bootstrap over sequences 95 % [{low:+.4f}, {high:+.4f}], "
                           f"P(mean > 0) {positive:.2f}")
    summary.append("grid: " + "; ".join(f"{g}: {asdict(s)}" for g, s in enumerate(GRID)))
    columns = list(folds[0])
    mean_row = ["mean", "", *(np.mean([float(str(f[c])) for f in folds]) for c in columns[2:])]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.out, csv_text(columns, [[f[c] for c in columns] for f in folds] + [mean_row]))
    write_text_atomic(summary_path, markdown(folds, summary))
    write_text_atomic(runs_path, csv_text(["run", "sequence", *COUNTS], [[key, seq, *(counts[c] for c in COUNTS)]
                                                                         for key, by_sequence in table.items()
                                                                         for seq, counts in by_sequence.items()]))
    print(markdown(folds, summary), end="")
    return 0


def _detections(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    det = read_detections(path)
    return det.frame, det.box, det.score
