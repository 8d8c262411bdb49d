#!/usr/bin/env python
"""Detector × filter table on seeded synthetic videos: raw success AUC and filtered AUC (rule, tuned).

    python scripts/video_table.py                              # 24 test + 16 train videos, all detectors
    python scripts/video_table.py --backends ufir_cmn kf --cache ~/.cache/bboxtune/video --out runs/video_table
    python scripts/video_table.py --tuned runs/ppo_ufir_cmn_video_s0     # a train.py run (or a tuned.json)

Videos: test split ``test-00000`` … (generator seeds 2 000 000 + i) and, for the tuned filter, the train split
``train-00000`` … (seeds 0 + i) of :mod:`envs.video.source` — never the same videos. For every detector and
back end: ``raw`` = the detector's boxes (missing frames count as failures), ``rule`` = the filter with the
fixed rule's parameters (nominal σ of the detector, N = N_opt), ``tuned`` = one action for the whole set,
grid-searched on the training videos for the best mean success AUC (:func:`envs.video.tuning.grid_tune`), or
the policy / action of ``--tuned``. Writes ``results.csv`` (one row per video × detector × back end × method),
``table.md`` (means; Δ = filtered − raw with a 95 % paired bootstrap interval over videos), ``summary.json``
and ``tuned/<detector>-<backend>.json`` (the grid-searched actions, reusable with ``--tuned``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402
from video_common import bootstrap_ci, write_csv, write_json, write_text  # noqa: E402

import filters  # noqa: E402
from envs.config import EnvConfig  # noqa: E402
from envs.scoring import run_positions, score_estimates  # noqa: E402
from envs.video.detectors import DETECTORS  # noqa: E402
from envs.video.source import VideoSettings, VideoSource  # noqa: E402
from envs.video.tuning import grid_tune, load_tuner, rule_params  # noqa: E402

METHODS = ("raw", "rule", "tuned")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--n-test", type=int, default=24, help="test videos (scored)")
    p.add_argument("--n-train", type=int, default=16, help="training videos (grid search of the tuned filter)")
    p.add_argument("--frames", type=int, default=200, help="frames per video (30 fps)")
    p.add_argument("--detectors", nargs="+", default=list(DETECTORS), choices=DETECTORS)
    p.add_argument("--backends", nargs="+", default=["ufir_cmn", "kf"], choices=filters.NAMES)
    p.add_argument("--grid", type=int, default=9, help="grid points per tuned parameter")
    p.add_argument("--tuned", default=None, help="train.py run directory or tuned.json (replaces the grid search; "
                                                 "its back end replaces --backends)")
    p.add_argument("--cache", default=None, help="folder of the detection cache (default: memory only)")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstrap intervals")
    p.add_argument("--out", default="runs/video_table", help="output folder")
    args = p.parse_args(argv)
    if args.n_test < 2 or args.n_train < 1 or args.frames < 8 or args.grid < 2:
        p.error("need --n-test >= 2, --n-train >= 1, --frames >= 8, --grid >= 2")
    return args


def episodes(detector: str, split: str, n: int, frames: int, cache: str | None) -> list:
    settings = VideoSettings(detector=detector, video_pool=n, video_cache=cache)
    source = VideoSource(EnvConfig(split=split, track_length=frames), settings)
    return [source.draw(name, 0) for name in tqdm(source.names, desc=f"{detector} {split}", leave=False)]


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    fixed = load_tuner(args.tuned) if args.tuned else None
    backends = [fixed.backend] if fixed else args.backends
    rng = np.random.default_rng(args.seed)
    rows, summary = [], {}
    for detector in args.detectors:
        test = episodes(detector, "test", args.n_test, args.frames, args.cache)
        train = episodes(detector, "train", args.n_train, args.frames, args.cache) if fixed is None else []
        raw = [score_estimates(ep.y[None], ep.truth) for ep in test]
        summary[detector] = {"raw_success_auc": float(np.mean([s["success_auc"][0] for s in raw])),
                             "missing_fraction": float(np.mean([ep.meta["n_missing"] / len(ep.y) for ep in test]))}
        for backend in backends:
            tuner = fixed
            if tuner is None:
                tuner, train_auc = grid_tune(train, backend, points=args.grid)
                tuner.save(out / "tuned" / f"{detector}-{backend}.json", detector=detector, train_success_auc=train_auc,
                           train_videos=[ep.meta["sequence"] for ep in train])
            auc = {m: [] for m in METHODS}
            for ep, raw_scores in zip(test, raw):
                for method, params in (("rule", rule_params(ep)), ("tuned", tuner.params(ep))):
                    est = run_positions(backend, ep.y, ep.tau, params)
                    scores = score_estimates(est, ep.truth)
                    auc[method].append(float(scores["success_auc"][0]))
                    rows.append(_row(ep, detector, backend, method, scores))
                auc["raw"].append(float(raw_scores["success_auc"][0]))
                rows.append(_row(ep, detector, backend, "raw", raw_scores))
            res = {}
            for method in ("rule", "tuned"):
                diff = np.array(auc[method]) - np.array(auc["raw"])
                res[method] = {"success_auc": float(np.mean(auc[method])), "delta_vs_raw": float(diff.mean()),
                               "delta_ci95": bootstrap_ci(diff, rng)}
            res["tuned"]["action"] = tuner.act(test[0]).tolist()
            summary[detector][backend] = res
            print(f"{detector:9s} {backend:9s} raw {np.mean(auc['raw']):.3f}  rule {res['rule']['success_auc']:.3f}"
                  f"  tuned {res['tuned']['success_auc']:.3f}", flush=True)
    header = ("video", "detector", "backend", "method", "success_auc", "precision20", "rmse", "n_missing")
    write_csv(out / "results.csv", header, rows)
    write_json(out / "summary.json", {"args": vars(args), "detectors": summary})
    write_text(out / "table.md", table(summary, backends, args))
    print(table(summary, backends, args))
    return 0


def _row(ep, detector: str, backend: str, method: str, scores: dict) -> tuple:
    return (ep.meta["sequence"], detector, backend, method, float(scores["success_auc"][0]),
            float(scores["precision20"][0]), float(scores["rmse"][0]), ep.meta["n_missing"])


def table(summary: dict, backends: list[str], args: argparse.Namespace) -> str:
    """Markdown table: mean success AUC per detector; filtered cells show Δ vs raw and its 95 % CI."""
    head = ["detector", "raw AUC", "missing %"] + [f"{m} {b}" for b in backends for m in ("rule", "tuned")]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for detector, s in summary.items():
        cells = [detector, f"{s['raw_success_auc']:.3f}", f"{100 * s['missing_fraction']:.1f}"]
        for b in backends:
            for m in ("rule", "tuned"):
                r = s[b][m]
                lo, hi = r["delta_ci95"]
                cells.append(f"{r['success_auc']:.3f} ({r['delta_vs_raw']:+.3f} [{lo:+.3f}, {hi:+.3f}])")
        lines.append("| " + " | ".join(cells) + " |")
    note = (f"\n{args.n_test} test videos × {args.frames} frames (320×240, 30 fps); tuned = grid search "
            f"({args.grid} points per parameter) on {args.n_train} separate training videos"
            if not args.tuned else f"\ntuned = {args.tuned}")
    return "\n".join(lines) + note + "; cells: mean AUC (Δ vs raw [95 % bootstrap CI over videos]).\n"


if __name__ == "__main__":
    raise SystemExit(main())
