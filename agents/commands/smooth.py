"""Smooth a tracker's OTB-format results with a learned tuner: parameters chosen per sequence from the
tracker's boxes alone (never the ground truth).

    python scripts/smooth.py --results trackers/SiamFC --out runs/SiamFC_smoothed
    python scripts/smooth.py --results trackers/SiamFC --out DIR --pretrained sim_ufir_cmn --otb-root $OTB_ROOT
    python scripts/smooth.py --results trackers/SiamFC --out DIR --model runs/ppo_ufir_cmn_otb_tracker_s0

--results holds one <Sequence>.txt per sequence (x,y,w,h per line, 1-based OTB pixels; 0,0,0,0 = no box), read
by the OTB readers (a malformed file stops the run with file:line, exit status 2, nothing written). Tuner:
--model RUN_DIR (a scripts/train.py run of bboxtune/FilterTune-v0) or --pretrained NAME (agents/pretrained);
neither: the pretrained tracker-output tuner otb_tracker_kf_cmn (gated: its gate leaves every sequence as
read; --no-gate smooths them). --tau: the frame interval in s (default: the tuner's otb_tau, 1/30 s). Every
sequence must have at least 8 frames, 2 of them with a box.

--out (absent or empty; it appears complete or not at all) receives one <Sequence>.txt per input file, same
name, x,y,w,h with 3 decimals per line, one line per input line: the back end's smoothed boxes. Frames
without a box in the input are predicted from the others; frames before the first box, and any frame whose
smoothed w or h is <= 0, are written 0,0,0,0 (counted in params.csv). A gated tuner (--gate FILE, a gate that
compare.py --gate fitted for this tuner, or a gate.json in the tuner's folder unless --no-gate; agents.gate) writes
a sequence where its gate stays closed as read instead. params.csv: sequence, n_frames, n_missing_in,
n_missing_out, left_alone (1: written as read) and the chosen parameters (e.g. psi, horizon; exact values; what the
model sets, also where the sequence is left alone). With --otb-root the sequences found there are scored, raw and smoothed, by scripts/otb_eval.py's scorer (success AUC, precision at
20 px, mean over sequences; printed and written to scores.csv).
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from agents import pretrained
from agents.cli import (ArgumentParser, HelpFormatter, argument_errors, existing_dir, existing_file, float_range,
                        out_dir)
from agents.commands.otb_eval import evaluate
from agents.tune import DEFAULT_PRETRAINED, TAU_RANGE, Tuner, check_boxes, load_pretrained
from agents.video_tables import csv_text, folder_in_use, publish_folder
from envs.data.otb import OTBDataset
from envs.data.otb_io import read_boxes
from envs.episodes.actions import ACCEPTS


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="smooth.py", description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("--results", type=existing_dir, required=True, metavar="DIR",
                   help="a tracker's result files <Sequence>.txt (OTB format)")
    p.add_argument("--out", type=out_dir, required=True, metavar="DIR", help="output folder, new or empty")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--model", type=existing_dir, default=None, metavar="RUN_DIR",
                       help="a scripts/train.py run directory (its final model)")
    which.add_argument("--pretrained", default=None, metavar="NAME",
                       help=f"a pretrained tuner (installed: {', '.join(pretrained.available()) or 'none'}; "
                            f"default {DEFAULT_PRETRAINED})")
    p.add_argument("--otb-root", default=None, metavar="ROOT",
                   help="OTB data (any layout of otb_eval.py): score raw and smoothed results")
    p.add_argument("--tau", type=float_range(*TAU_RANGE), default=None, metavar="S",
                   help="frame interval in s (default: the tuner's otb_tau)")
    gating = p.add_mutually_exclusive_group()
    gating.add_argument("--gate", type=existing_file, default=None, metavar="FILE",
                        help="a gate file of compare.py --gate (gates/<name>.json, fitted for this tuner): sequences "
                             "where it stays closed are written as read (default: the tuner folder's gate.json, if any)")
    gating.add_argument("--no-gate", action="store_true",
                        help="ignore the tuner folder's gate.json: smooth every sequence")
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
    lines = [",".join(f"{v:.3f}" for v in box) if ok else "0,0,0,0" for box, ok in zip(boxes, written)]
    return "\n".join(lines) + "\n", int((~written).sum())


def score(otb_root: str, results: Path) -> dict[str, float | int]:
    """otb_eval.py's sequence-averaged scores of the result folder ``results`` (scored as a tracker of its own)."""
    folder = results.resolve()
    return evaluate(OTBDataset(otb_root, trackers_root=folder.parent), [folder.name])[folder.name]


def score_smoothed(otb_root: str, files: dict[str, str]) -> dict[str, float | int]:
    """:func:`score` of the smoothed files as they will be written (a temporary folder holds them meanwhile)."""
    with tempfile.TemporaryDirectory(prefix="smooth-") as tmp:
        folder = Path(tmp) / "smoothed"
        folder.mkdir()
        for name, text in files.items():
            (folder / name).write_text(text, encoding="utf-8")
        return score(otb_root, folder)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    reason = folder_in_use(args.out)
    if reason is not None:
        parser.error(f"--out {reason}; choose another --out")
    with argument_errors(parser, "--results"):
        results = read_results(args.results)
    with argument_errors(parser, "--model" if args.model else "--pretrained"):
        tuner = Tuner.from_run(args.model) if args.model else load_pretrained(args.pretrained or DEFAULT_PRETRAINED)
    if args.gate is not None:
        with argument_errors(parser, "--gate"):
            tuner = tuner.with_gate(args.gate)
    if args.no_gate:
        tuner = replace(tuner, gate=None)
    tau = args.tau if args.tau is not None else tuner.config.otb_tau
    raw = None
    if args.otb_root is not None:
        with argument_errors(parser, "--otb-root"):
            raw = score(args.otb_root, args.results)
    files, rows = {}, []
    for name, (path, boxes) in tqdm(results.items(), desc=f"smooth ({tuner.name})", unit="seq"):
        seen = tuner.observe(boxes, tau)
        params, alone = tuner.params(seen), tuner.leaves_alone(seen)
        files[name], n_missing_out = box_text(boxes if alone else tuner.smooth(boxes, tau, params))
        n_missing_in = int(np.isnan(boxes).all(axis=1).sum())
        rows.append([path.stem, len(boxes), n_missing_in, n_missing_out, int(alone),
                     *(str(v) for v in params.values())])  # exact
    files["params.csv"] = csv_text(["sequence", "n_frames", "n_missing_in", "n_missing_out", "left_alone",
                                    *ACCEPTS[tuner.backend]], rows)
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
    with argument_errors(parser, "--out"):
        publish_folder(args.out, files)
    print(f"wrote {args.out}")
    return 0

