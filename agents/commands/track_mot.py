"""Track MOT Challenge detections with a SORT-style tracker and a pluggable box filter (bboxtune.agents.tracking).

    python scripts/track_mot.py --det ../shared/data/mot15/KITTI-13/det/det.txt --filter sort_kf --out runs/sort/KITTI-13.txt
    python scripts/track_mot.py --det DET.txt --fps 30 --filter tuned --pretrained mot15_det --out runs/tuned/SEQ.txt
    python scripts/track_mot.py --det DET.txt --filter kf --params sigma_w=300 sigma_v=3 --two-stage --out OUT.txt

Every frame: each track's filter predicts its box, the frame's detections are matched to the predictions
(Hungarian on IoU, --iou-threshold; with --two-stage ByteTrack's high/low score stages), matched tracks update
their filter, unmatched detections start tracks, a track unmatched for more than --max-age frames ends, and a
track matched in this frame and in --min-hits frames in a row is written (SORT's rules and defaults:
max_age 1, min_hits 3, iou_threshold 0.3). --filter: sort_kf (SORT's filter), bytetrack_kf (ByteTrack's), any
other back end of bboxtune.filters with --params, or tuned: a trained tuner (--pretrained NAME, default mot15_det,
or --model RUN_DIR) re-tunes each track's filter every --retune-window frames from that track's own past
detections only, starting from the back end's stock parameters; or search: SORT's filter with two noise scales
chosen per track every --retune-window frames from a candidate grid (--search-width) by how well each candidate
would have predicted the track's own past matched detections (IoU counted up to --search-cap; SORT's stock filter
until --search-min-scored frames are scored, and preferred unless another is better by --search-margin):
bboxtune.agents.tracking.search_tune. Causal throughout: frame t uses detections up to t.

The frame rate (the filters' tau = 1/fps) is --fps, else the seqinfo.ini beside the det file (its folder or the
one above), else the sequences.csv of the data the det file belongs to (three folders up:
<root>/<sequence>/det/det.txt), else of --mot-root / $MOT_ROOT. --min-score drops detections below it first.

Writes --out (a new file, atomically; missing folders created) in the MOT Challenge result format, one line per box:
frame, id, x, y, w, h, score, -1, -1, -1 (xywh px, the filtered box; score: the matched detection's). Identities
count from 1. Score it with scripts/eval_mot.py. Bad input: one line naming the flag or file:line, exit status 2,
nothing written.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bboxtune import filters
from bboxtune.agents.cli import (
    ArgumentParser,
    HelpFormatter,
    command,
    existing_dir,
    existing_file,
    float_range,
    int_range,
    key_values,
    new_file,
)
from bboxtune.agents.smoothing.mot_smooth import check_fps, find_seqinfo, read_seqinfo_fps
from bboxtune.agents.smoothing.tuner import Tuner, load_pretrained
from bboxtune.agents.tracking.search_tune import SearchSettings
from bboxtune.agents.tracking.sort_tracker import SEARCH, TUNED, Tracker, TrackerConfig, make_tracker
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.data.mot import resolve_root
from bboxtune.envs.data.mot_io import Detections, read_detections, read_sequences_csv

FILTERS = ("sort_kf", "bytetrack_kf", *filters.NAMES, TUNED, SEARCH)
SEARCH_FLAGS = {"--search-width": "width", "--search-cap": "cap", "--search-margin": "margin",
                "--search-min-scored": "min_scored"}  # flag -> SearchSettings field
DEFAULT_PRETRAINED = "mot15_det"


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="track_mot.py", description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("--det", required=True, type=existing_file, help="detections, MOT Challenge det.txt format")
    p.add_argument("--out", required=True, type=new_file, help="the result file to write (must not exist)")
    p.add_argument("--fps", type=float_range(1.0, 1000.0), default=None, help="frame rate (default: seqinfo.ini / sequences.csv)")
    p.add_argument("--mot-root", type=existing_dir, default=None, help="a MOT data folder whose sequences.csv gives the rate")
    p.add_argument("--filter", choices=FILTERS, default="sort_kf", help="the box filter of every track")
    p.add_argument("--params", nargs="*", default=[], metavar="KEY=VALUE", help="the back end's parameters (not with tuned)")
    p.add_argument("--pretrained", default=None, metavar="NAME", help=f"tuned: a pretrained tuner (default {DEFAULT_PRETRAINED})")
    p.add_argument("--model", type=existing_dir, default=None, metavar="RUN_DIR", help="tuned: a train.py run as the tuner")
    p.add_argument("--retune-window", type=int_range(1, 10**6), default=None,
                   help=f"tuned / search: frames between re-tunes (default 10 / {SearchSettings.window})")
    p.add_argument("--retune-history", type=int_range(8, 10**6), default=None,
                   help=f"tuned / search: past frames seen (default 100 / {SearchSettings.history})")
    p.add_argument("--search-width", type=float_range(1.0, 1e6), default=None,
                   help=f"search: the candidates' largest noise scale (default {SearchSettings.width:g})")
    p.add_argument("--search-cap", type=float_range(0.0, 1.0, low_open=True), default=None,
                   help=f"search: IoU counted up to this (default {SearchSettings.cap:g})")
    p.add_argument("--search-margin", type=float_range(0.0, 1.0), default=None,
                   help=f"search: mean IoU a candidate must gain over SORT's filter (default {SearchSettings.margin:g})")
    p.add_argument("--search-min-scored", type=int_range(1, 10**6), default=None,
                   help=f"search: scored frames before a track leaves SORT's filter (default {SearchSettings.min_scored})")
    p.add_argument("--max-age", type=int_range(0, 10**6), default=1, help="frames a track lives without a match")
    p.add_argument("--min-hits", type=int_range(0, 10**6), default=3, help="matches in a row before a track is written")
    p.add_argument("--iou-threshold", type=float_range(0.0, 1.0, low_open=True), default=0.3, help="least IoU of a match")
    p.add_argument("--two-stage", action="store_true", help="ByteTrack's association by detection score")
    p.add_argument("--high-score", type=float_range(), default=0.5, help="two-stage: first-stage detections' least score")
    p.add_argument("--low-score", type=float_range(), default=0.1, help="two-stage: detections below are dropped")
    p.add_argument("--new-track-score", type=float_range(), default=0.6, help="two-stage: least score to start a track")
    p.add_argument("--low-iou-threshold", type=float_range(0.0, 1.0, low_open=True), default=0.5,
                   help="two-stage: least IoU of a low-score match")
    p.add_argument("--min-score", type=float_range(), default=None, help="drop detections scored below this first")
    return p


def frame_rate(det: Path, fps: float | None, mot_root: Path | None) -> float:
    """The module docstring's frame rate for the det file ``det`` (ValueError naming the file, or saying to pass --fps)."""
    if fps is not None:
        return check_fps(fps, "--fps")
    ini = find_seqinfo(det)
    if ini is not None:
        return read_seqinfo_fps(ini)
    sequence_folder = Path(os.path.abspath(det)).parent.parent
    roots = [sequence_folder.parent] if (sequence_folder.parent / "sequences.csv").is_file() else []
    if mot_root is not None or os.environ.get("MOT_ROOT"):
        roots.append(resolve_root(mot_root))
    for root in roots:
        table = read_sequences_csv(root)
        if sequence_folder.name in table:
            return check_fps(float(table[sequence_folder.name].fps), str(root / "sequences.csv"))
    raise ValueError(f"--det {det}: no frame rate: no seqinfo.ini beside it and no sequences.csv row "
                     f"{sequence_folder.name!r}; pass --fps F")


def track(tracker: Tracker, det: Detections, min_score: float | None, name: str
          ) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """(frame, ids, boxes, scores) of every frame 1 … the last detection's, detections below ``min_score`` dropped
    (a progress bar on a terminal)."""
    keep = det.score >= min_score if min_score is not None else np.ones(len(det.frame), dtype=bool)
    n_frames = int(det.frame.max()) if len(det.frame) else 0
    frames = tracker.run(det.frame[keep], det.box[keep], det.score[keep], n_frames)
    return [(r.frame, r.ids, r.boxes, r.scores)
            for r in tqdm(frames, total=n_frames, unit="frame", desc=name, disable=None, leave=False)]


def result_lines(rows: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]) -> str:
    """The MOT Challenge result text of (frame, ids, boxes, scores) per frame."""
    return "".join(f"{frame},{i},{b[0]:.3f},{b[1]:.3f},{b[2]:.3f},{b[3]:.3f},{s:.3f},-1,-1,-1\n"
                   for frame, ids, boxes, scores in rows for i, b, s in zip(ids, boxes, scores, strict=True))


@command
def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring); exit status 0, 2 for bad input (one line)."""
    p = build_parser()
    args = p.parse_args(argv)
    tuned = args.filter == TUNED
    if not tuned and (args.pretrained or args.model):
        p.error(f"--pretrained / --model: only with --filter {TUNED}")
    search_given = {field: getattr(args, flag[2:].replace("-", "_")) for flag, field in SEARCH_FLAGS.items()}
    if args.filter != SEARCH and any(value is not None for value in search_given.values()):
        p.error(f"{', '.join(SEARCH_FLAGS)}: only with --filter {SEARCH}")
    if args.filter not in (TUNED, SEARCH) and (args.retune_window or args.retune_history):
        p.error(f"--retune-window / --retune-history: only with --filter {TUNED} or {SEARCH}")
    if args.filter == SEARCH and args.params:
        p.error(f"--params: not with --filter {SEARCH} (the search sets the parameters)")
    if tuned and args.params:
        p.error(f"--params: not with --filter {TUNED} (the tuner sets the parameters)")
    if args.pretrained and args.model:
        p.error("--pretrained / --model: one of them")
    try:
        params = key_values("--params", args.params)
        tuner: Tuner | None = None
        if tuned:
            tuner = Tuner.from_run(args.model) if args.model else load_pretrained(args.pretrained or DEFAULT_PRETRAINED)
        det = read_detections(args.det)
        tau = 1.0 / frame_rate(args.det, args.fps, args.mot_root)
        config = TrackerConfig(max_age=args.max_age, min_hits=args.min_hits, iou_threshold=args.iou_threshold,
                               two_stage=args.two_stage, high_score=args.high_score, low_score=args.low_score,
                               low_iou_threshold=args.low_iou_threshold, new_track_score=args.new_track_score)
        retune = {name: value for name, value in (("window", args.retune_window), ("history", args.retune_history))
                  if value is not None}
        if args.filter == SEARCH:
            given = {**retune, **{field: value for field, value in search_given.items() if value is not None}}
            tracker = make_tracker(SEARCH, tau, config=config, search=SearchSettings(**given))
        else:
            tracker = make_tracker(args.filter, tau, params=params, tuner=tuner, config=config, **retune)
    except (ValueError, TypeError, OSError) as err:
        p.error(str(err))
    rows = track(tracker, det, args.min_score, args.det.parent.parent.name)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.out, result_lines(rows))
    n_boxes, n_ids = sum(len(r[1]) for r in rows), len({int(i) for r in rows for i in r[1]})
    print(f"{len(rows)} frames, {n_boxes} boxes, {n_ids} identities -> {args.out}")
    return 0
