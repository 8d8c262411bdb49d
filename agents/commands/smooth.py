"""Smooth a tracker's OTB-format results with a learned tuner: parameters chosen per sequence from the
tracker's boxes alone (never the ground truth).

    python scripts/smooth.py --results trackers/SiamFC --out runs/SiamFC_smoothed
    python scripts/smooth.py --results trackers/SiamFC --out DIR --pretrained sim_ufir_cmn --otb-root $OTB_ROOT
    python scripts/smooth.py --results trackers/SiamFC --out DIR --model runs/ppo_ufir_cmn_otb_tracker_s0

--results holds one <Sequence>.txt per sequence (x,y,w,h per line, 1-based OTB pixels; 0,0,0,0 = no box), read
by the OTB readers (a malformed file stops the run with file:line, exit status 2, nothing written). Tuner:
--model RUN_DIR (a scripts/train.py run of bboxtune/FilterTune-v0) or --pretrained NAME (agents/pretrained);
neither: the pretrained tracker-output tuner otb_tracker_kf_cmn (gated: its gate leaves every sequence as
read; --no-gate smooths them). No tuner: --filter bytetrack_kf / sort_kf, the box Kalman filter ByteTrack /
DeepSORT or SORT ship, with its published settings (bboxtune.agents.smoothing.stock_filter; for either format). --tau: the
frame interval in s (default: the tuner's otb_tau, 1/30 s). Every
sequence must have at least 8 frames, 2 of them with a box.

--out (absent or empty; it appears complete or not at all) receives one <Sequence>.txt per input file, same
name, x,y,w,h with 3 decimals per line, one line per input line: the back end's smoothed boxes. Frames
without a box in the input are predicted from the others; frames before the first box, and any frame whose
smoothed w or h is <= 0, are written 0,0,0,0 (counted in params.csv). A gated tuner (--gate FILE, a gate that
compare.py --gate fitted for this tuner, or a gate.json in the tuner's folder unless --no-gate;
bboxtune.agents.evaluation.gate) writes a sequence where its gate stays closed as read instead: the input file's
bytes, unchanged. params.csv: sequence, n_frames, n_missing_in, n_missing_out, left_alone (1: written as read) and
the chosen parameters (e.g. psi, horizon; exact values; what the model sets, also where the sequence is left alone).
With --otb-root the sequences found there are scored, raw and smoothed, by scripts/otb_eval.py's scorer (success
AUC, precision at 20 px, mean over sequences; printed and written to scores.csv); the smoothed files are scored
from a temporary folder (smooth-*), removed also when Ctrl-C or SIGTERM stops the run (one line, exit status 130 /
143; --out is then not written).

--format mot (default otb: all of the above) smooths MOT Challenge tracks one identity at a time
(agents/smoothing/mot_smooth.py):

    python scripts/smooth.py --format mot --results trackers/MyTracker/data --out DIR --fps 30
    python scripts/smooth.py --format mot --results $MOT_ROOT/KITTI-13 --out DIR --pretrained otb_kf_cmn

--results is a MOT result file (frame,id,x,y,w,h,score,X,Y,Z per line: 1-based frames, xywh px), a folder of
<Sequence>.txt result files, or a sequence folder with det/det.txt and gt/gt.txt (MOT15 layout: its public
detections matched to the ground-truth identities, IoU >= 0.5; unmatched ones are dropped), read by the MOT
readers (file:line errors). A track (one id) runs from its first to its last frame; frames in between without a
row are gaps, filled with the filter's prediction. Each track gets the tuner's parameters for its own boxes; a
track under 8 frames, or one the gate leaves alone, is written as read (its lines byte for byte). Frame rate:
--fps F, else frameRate= of [Sequence] in a seqinfo.ini in the file's folder or the folder above it, else the
sequence's fps in the sequences.csv of --mot-root (default $MOT_ROOT), else an error; 1 <= fps <= 1000 (tau =
1/fps). --out (as above) receives one <name>.txt per input (a sequence folder: <folder name>.txt) with lines
frame,id,x,y,w,h,score,-1,-1,-1 sorted by frame then id, boxes with 3 decimals: input rows keep their score,
filled gap rows have score -1; a box whose w or h is <= 0 is not written. params.csv: file, identity, fps,
n_frames (first to last frame), n_rows_in, n_filled, n_dropped (boxes not written), left_alone (1: written as
read) and the chosen parameters (empty for a track too short to tune). --tau and --otb-root are for --format otb,
--fps and --mot-root for --format mot.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from bboxtune.agents.cli import (
    ArgumentParser,
    HelpFormatter,
    argument_errors,
    command,
    existing_dir,
    existing_file,
    float_range,
    out_dir,
)
from bboxtune.agents.commands.otb_eval import evaluate
from bboxtune.agents.evaluation.video_tables import csv_text, folder_in_use, publish_folder, write_content
from bboxtune.agents.smoothing import mot_smooth, pretrained
from bboxtune.agents.smoothing.stock_filter import STOCK_FILTERS, StockFilter, TrackSmoother
from bboxtune.agents.smoothing.tuner import DEFAULT_PRETRAINED, MIN_FRAMES, TAU_RANGE, Tuner, check_boxes, load_pretrained
from bboxtune.envs.data.mot import MOT_ROOT_ENV
from bboxtune.envs.data.otb import OTBDataset
from bboxtune.envs.data.otb_io import read_boxes
from bboxtune.envs.data.textfile import read_bytes

FORMAT_ONLY = {"--tau": "otb", "--otb-root": "otb", "--fps": "mot", "--mot-root": "mot"}


def existing_path(text: str) -> Path:
    """``type=`` for a path that exists (--results: a folder for otb; a file or a folder for mot)."""
    if not text or not Path(text).exists():
        raise argparse.ArgumentTypeError(f"{text!r} does not exist")
    return Path(text)


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="smooth.py", description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("--format", choices=("otb", "mot"), default="otb",
                   help="otb: OTB result files, one track each; mot: MOT tracks, smoothed per identity")
    p.add_argument("--results", type=existing_path, required=True, metavar="PATH",
                   help="otb: a folder of a tracker's result files <Sequence>.txt; mot: a result file, a folder of "
                        "them, or a sequence folder with det/det.txt and gt/gt.txt")
    p.add_argument("--out", type=out_dir, required=True, metavar="DIR", help="output folder, new or empty")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--model", type=existing_dir, default=None, metavar="RUN_DIR",
                       help="a scripts/train.py run directory (its final model)")
    which.add_argument("--pretrained", default=None, metavar="NAME",
                       help=f"a pretrained tuner (installed: {', '.join(pretrained.available()) or 'none'}; "
                            f"default {DEFAULT_PRETRAINED})")
    which.add_argument("--filter", choices=STOCK_FILTERS, default=None,
                       help="no tuner: the box Kalman filter a tracker ships, with its published settings "
                            "(ByteTrack / DeepSORT's or SORT's)")
    p.add_argument("--otb-root", default=None, metavar="ROOT",
                   help="otb: OTB data (any layout of otb_eval.py): score raw and smoothed results")
    p.add_argument("--tau", type=float_range(*TAU_RANGE), default=None, metavar="S",
                   help="otb: frame interval in s (default: the tuner's otb_tau)")
    p.add_argument("--fps", type=float_range(*mot_smooth.FPS_RANGE), default=None, metavar="F",
                   help="mot: frames per second of every input (default: its seqinfo.ini, else sequences.csv)")
    p.add_argument("--mot-root", type=existing_dir, default=None, metavar="ROOT",
                   help=f"mot: a MOT root whose sequences.csv gives the frame rate of a sequence without seqinfo.ini "
                        f"(default ${MOT_ROOT_ENV})")
    gating = p.add_mutually_exclusive_group()
    gating.add_argument("--gate", type=existing_file, default=None, metavar="FILE",
                        help="a gate file of compare.py --gate (gates/<name>.json, fitted for this tuner): sequences "
                             "(mot: tracks) where it stays closed are written as read (default: the tuner folder's "
                             "gate.json, if any)")
    gating.add_argument("--no-gate", action="store_true",
                        help="ignore the tuner folder's gate.json: smooth every sequence (mot: every track)")
    return p


def read_results(folder: Path) -> dict[str, tuple[Path, np.ndarray]]:
    """{file name: (path, boxes (T, 4) xywh, NaN rows = no box)} of the ``*.txt`` files in ``folder``, checked
    (file:line errors from the OTB readers; too short a sequence names its file)."""
    paths = sorted(p for p in folder.iterdir() if p.suffix == ".txt")
    if not paths:
        raise ValueError(f"{folder} holds no <Sequence>.txt result files")
    results = {}
    for path in paths:
        results[path.name] = (path, check_boxes(read_boxes(path), str(path)))
    return results


def box_text(boxes: np.ndarray) -> tuple[str, int]:
    """OTB box text of ``boxes`` (T, 4) xywh, 3 decimals, ``0,0,0,0`` where a box is missing or has w or h <= 0
    (it would not read back as a box); and how many such lines."""
    written = np.isfinite(boxes).all(axis=1) & (np.round(boxes[:, 2:], 3) > 0).all(axis=1)
    lines = [",".join(f"{v:.3f}" for v in box) if ok else "0,0,0,0" for box, ok in zip(boxes, written, strict=False)]
    return "\n".join(lines) + "\n", int((~written).sum())


def score(otb_root: str, results: Path) -> dict[str, float | int]:
    """otb_eval.py's sequence-averaged scores of the result folder ``results`` (scored as a tracker of its own)."""
    folder = results.resolve()
    return evaluate(OTBDataset(otb_root, trackers_root=folder.parent), [folder.name])[folder.name]


def score_smoothed(otb_root: str, files: dict[str, str | bytes]) -> dict[str, float | int]:
    """:func:`score` of the smoothed files as they will be written (a temporary folder holds them meanwhile)."""
    with tempfile.TemporaryDirectory(prefix="smooth-") as tmp:
        folder = Path(tmp) / "smoothed"
        folder.mkdir()
        for name, content in files.items():
            write_content(folder / name, content)
        return score(otb_root, folder)


def load_tuner(parser: ArgumentParser, args: argparse.Namespace) -> TrackSmoother[Any]:
    """The tuner of --model / --pretrained, gated as --gate / --no-gate say, or the stock filter of --filter."""
    if args.filter is not None:
        if args.gate is not None or args.no_gate:
            parser.error("--gate / --no-gate apply to a tuner, not to --filter")
        return StockFilter(args.filter)
    with argument_errors(parser, "--model" if args.model else "--pretrained"):
        tuner = Tuner.from_run(args.model) if args.model else load_pretrained(args.pretrained or DEFAULT_PRETRAINED)
    if args.gate is not None:
        with argument_errors(parser, "--gate"):
            tuner = tuner.with_gate(args.gate)
    return replace(tuner, gate=None) if args.no_gate else tuner


def smooth_mot(parser: ArgumentParser, args: argparse.Namespace) -> dict[str, str | bytes]:
    """--format mot: the output files (bboxtune.agents.smoothing.mot_smooth; a summary is printed)."""
    with argument_errors(parser, "--results"):
        inputs = mot_smooth.read_inputs(args.results)
    with argument_errors(parser, "--fps"):
        root = args.mot_root or os.environ.get(MOT_ROOT_ENV) or None
        rates = mot_smooth.frame_rates(inputs, args.fps, root)
    tuner = load_tuner(parser, args)
    keys = tuner.parameters
    files: dict[str, str | bytes] = {}
    table: list[list[Any]] = []
    done: list[tuple[mot_smooth.Smoothed, mot_smooth.Rows]] = []
    for item, rate in zip(inputs, rates, strict=True):
        print(f"{item.name}: {len(item.tracks)} identities, {rate.fps:g} fps ({rate.source})"
              + (f"; {item.n_unmatched} detections matched to no identity are not written" if item.n_unmatched else ""))
        smoothed = [mot_smooth.smooth_track(tuner, track, 1.0 / rate.fps)
                    for track in tqdm(item.tracks, desc=f"smooth {item.name} ({tuner.name})", unit="id")]
        rows = [mot_smooth.track_rows(s) for s in smoothed]
        files[item.name] = mot_smooth.file_text(rows)
        table += [mot_smooth.params_row(item.name, rate.fps, s, r, keys) for s, r in zip(smoothed, rows, strict=True)]
        done += zip(smoothed, rows, strict=True)
    files["params.csv"] = csv_text(mot_smooth.params_header(keys), table)
    short = sum(s.params is None for s, _ in done)
    gated = sum(s.left_alone for s, _ in done) - short
    print(f"smoothed {len(done) - short - gated} of {len(done)} identities with {tuner.name} ({tuner.backend}); "
          f"written as read: {short} under {MIN_FRAMES} frames" + (f", {gated} left by the gate" if tuner.gate else "")
          + f"; {sum(r.n_filled for _, r in done)} gap rows filled, {sum(r.n_dropped for _, r in done)} boxes with "
          "w or h <= 0 not written")
    return files


def smooth_otb(parser: ArgumentParser, args: argparse.Namespace) -> dict[str, str | bytes]:
    """--format otb: the output files (a summary and, with --otb-root, the scores are printed)."""
    with argument_errors(parser, "--results"):
        results = read_results(args.results)
    tuner = load_tuner(parser, args)
    tau = args.tau if args.tau is not None else tuner.config.otb_tau
    raw = None
    if args.otb_root is not None:
        with argument_errors(parser, "--otb-root"):
            raw = score(args.otb_root, args.results)
    files: dict[str, str | bytes] = {}
    rows: list[list] = []
    for name, (path, boxes) in tqdm(results.items(), desc=f"smooth ({tuner.name})", unit="seq"):
        seen = tuner.observe(boxes, tau)
        params, alone = tuner.params(seen), tuner.leaves_alone(seen)
        files[name], n_missing_out = box_text(boxes if alone else tuner.smooth(boxes, tau, params))
        if alone:
            files[name] = read_bytes(path)  # left alone: written byte for byte as read
        n_missing_in = int(np.isnan(boxes).all(axis=1).sum())
        rows.append([path.stem, len(boxes), n_missing_in, n_missing_out, int(alone),
                     *(str(v) for v in params.values())])  # exact
    files["params.csv"] = csv_text(["sequence", "n_frames", "n_missing_in", "n_missing_out", "left_alone",
                                    *tuner.parameters], rows)
    left = sum(row[4] for row in rows)
    print(f"smoothed {len(results) - left} of {len(results)} sequences with {tuner.name} ({tuner.backend}, tau {tau:.4g} s)"
          + (f"; the gate left {left} as read" if tuner.gate is not None else ""))
    if raw is not None:
        with argument_errors(parser, "--otb-root"):
            smoothed = score_smoothed(args.otb_root, files)
        table = [[kind, row["n_sequences"], row["success_auc"], row["precision20"]]
                 for kind, row in (("raw", raw), ("smoothed", smoothed))]
        files["scores.csv"] = csv_text(["results", "n_sequences", "success_auc", "precision20"], table)
        print(f"{'':<9} {'seqs':>5} {'success AUC':>12} {'precision@20px':>15}")
        for kind, n, auc, prec in table:
            print(f"{kind:<9} {n:>5} {auc:>12.3f} {prec:>15.3f}")
    return files


@command
def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    for flag, fmt in FORMAT_ONLY.items():
        if fmt != args.format and getattr(args, flag[2:].replace("-", "_")) is not None:
            parser.error(f"{flag} is for --format {fmt}, not --format {args.format}")
    if args.format == "otb":
        try:
            existing_dir(str(args.results))
        except argparse.ArgumentTypeError as err:
            parser.error(f"argument --results: {err}")
    torch.set_num_threads(1)
    reason = folder_in_use(args.out)
    if reason is not None:
        parser.error(f"--out {reason}; choose another --out")
    files = smooth_mot(parser, args) if args.format == "mot" else smooth_otb(parser, args)
    with argument_errors(parser, "--out"):
        publish_folder(args.out, files)
    print(f"wrote {args.out}")
    return 0
