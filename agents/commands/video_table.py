"""Detector × filter table on seeded synthetic videos: raw success AUC and filtered AUC (rule, tuned).

    python scripts/video_table.py                              # 100 test + 16 train videos, all detectors
    python scripts/video_table.py --backends ufir_cmn kf --cache ~/.cache/bboxtune/video --out runs/video_table
    python scripts/video_table.py --tuned runs/ppo_ufir_cmn_video_s0     # a train.py run (or a tuned.json)

Videos: test split ``test-00000`` … (generator seeds 2 000 000 + i) and, for the tuned filter, the train split
``train-00000`` … (seeds 0 + i) of :mod:`bboxtune.envs.episodes.video_source` — never the same videos. For every detector and
back end: ``raw`` = the detector's boxes (missing frames count as failures), ``rule`` = the filter with the
fixed rule's parameters (nominal σ of the detector, N = N_opt), ``tuned`` = one action for the whole set,
grid-searched on the training videos for the best mean success AUC (:func:`bboxtune.agents.smoothing.video_tuning.grid_tune`), or
the policy / action of ``--tuned``.

Writes into ``--out`` (absent or empty; the folder appears complete at the end of the run, or not at all):
``results.csv`` (one row per video × detector × back end × method), ``table.md`` (means, Δ = filtered − raw
with a 95 % paired bootstrap interval over videos; and each detector's worst video: the lowest AUC and which
video), ``summary.json`` and ``tuned/<detector>-<backend>.json`` (the grid-searched actions, reusable with
``--tuned``). The command line is checked before any work: a bad value exits 2 with one line naming the flag.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from bboxtune.agents.cli import ArgumentParser, HelpFormatter, argument_errors, command, int_range, nonnegative_int, out_dir
from bboxtune.agents.evaluation.stats import paired_mean_ci
from bboxtune.agents.evaluation.video_tables import csv_text, folder_in_use, json_text, publish_folder
from bboxtune.agents.smoothing.video_tuning import EpisodeTuner, action_map, grid_tune, load_tuner
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.config import TRACK_LENGTH_MAX, EnvConfig
from bboxtune.envs.episodes.scoring import run_positions, score_estimates
from bboxtune.envs.episodes.video_source import VideoSettings, VideoSource
from bboxtune.envs.video.detectors import DETECTORS

METHODS = ("raw", "rule", "tuned")
MAX_VIDEOS = 1_000_000  # videos per split (bboxtune.envs.episodes.video_source.VideoSettings.video_pool)
MAX_CANDIDATES = 10_000  # grid points per back end (each one filters every training video)


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="video_table.py", description=__doc__, formatter_class=HelpFormatter, allow_abbrev=False)
    p.add_argument("--n-test", type=int_range(2, MAX_VIDEOS), default=100, help="test videos (scored)")
    p.add_argument("--n-train", type=int_range(1, MAX_VIDEOS), default=16,
                   help="training videos (grid search of the tuned filter)")
    p.add_argument("--frames", type=int_range(8, TRACK_LENGTH_MAX), default=200, help="frames per video (30 fps)")
    p.add_argument("--detectors", nargs="+", default=None, choices=DETECTORS, metavar="NAME",
                   help=f"detectors, of {', '.join(DETECTORS)} (default: all)")
    p.add_argument("--backends", nargs="+", default=None, choices=BACKENDS, metavar="NAME",
                   help=f"filter back ends, of {', '.join(BACKENDS)} (default: ufir_cmn kf; with --tuned: "
                        "the tuner's)")
    p.add_argument("--grid", type=int_range(2, MAX_CANDIDATES), default=9,
                   help=f"grid points per tuned parameter (at most {MAX_CANDIDATES} grid points in all)")
    p.add_argument("--tuned", default=None, help="train.py run directory or tuned.json (replaces the grid search; "
                                                 "its back end replaces --backends)")
    p.add_argument("--trust-pickle", action="store_true",
                   help="--tuned RUN_DIR: accept an old run's pickled vecnormalize.pkl (pickles can run code)")
    p.add_argument("--cache", type=out_dir, default=None,
                   help="folder of the detection cache, created if missing (default: memory only)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the bootstrap intervals")
    p.add_argument("--out", type=out_dir, default="runs/video_table", help="output folder (absent or empty)")
    return p


def parse_args(argv: list[str] | None = None) -> tuple[argparse.Namespace, EpisodeTuner | None]:
    """The checked command line and the ``--tuned`` tuner (None: grid search); exit 2 with one line on misuse."""
    p = build_parser()
    args = p.parse_args(argv)
    with argument_errors(p, "--frames"):
        EnvConfig(track_length=args.frames)
    busy = folder_in_use(args.out)
    if busy:
        p.error(f"--out {busy}; choose another folder")
    out = args.out.resolve()
    if args.cache is not None and (args.cache.resolve() == out or out in args.cache.resolve().parents):
        p.error(f"--cache {args.cache} lies in --out {args.out}, which must stay empty until the table is written")
    tuner = None
    if args.tuned is not None:
        try:
            tuner = load_tuner(args.tuned, trust_pickle=args.trust_pickle)
        except (ValueError, OSError) as err:  # the message names the file (and --tuned when it is unusable)
            p.error(str(err) if str(err).startswith("--tuned") else f"--tuned: {err}")
        if args.backends not in (None, [tuner.backend]):
            p.error(f"--backends {' '.join(args.backends)} differs from the --tuned back end {tuner.backend}")
        args.backends = [tuner.backend]
    elif args.trust_pickle:
        p.error("--trust-pickle applies to --tuned RUN_DIR only")
    args.backends = args.backends or ["ufir_cmn", "kf"]
    args.detectors = args.detectors or list(DETECTORS)
    if len(set(args.backends)) < len(args.backends) or len(set(args.detectors)) < len(args.detectors):
        p.error("--backends and --detectors must not repeat a name")
    for backend in args.backends if tuner is None else ():
        n = args.grid ** action_map(backend).dim
        if n > MAX_CANDIDATES:
            p.error(f"--grid {args.grid}: {n} grid points for {backend}; allowed: at most {MAX_CANDIDATES}")
    return args, tuner


def episodes(detector: str, split: str, n: int, frames: int, cache: Path | None) -> list:
    settings = VideoSettings(detector=detector, video_pool=n, video_cache=None if cache is None else str(cache))
    source = VideoSource(EnvConfig(split=split, track_length=frames), settings)
    return [source.draw(name, 0) for name in tqdm(source.names, desc=f"{detector} {split}", leave=False)]


def worst(auc: list[float], videos: list[str]) -> dict[str, float | str]:
    """The lowest AUC of a method over the test videos and the video it came from."""
    i = int(np.argmin(auc))
    return {"success_auc": float(auc[i]), "video": videos[i]}


@command
def main(argv: list[str] | None = None) -> int:
    args, fixed = parse_args(argv)
    rng = np.random.default_rng(args.seed)
    rows, summary, tuned_files = [], {}, {}
    for detector in args.detectors:
        test = episodes(detector, "test", args.n_test, args.frames, args.cache)
        train = episodes(detector, "train", args.n_train, args.frames, args.cache) if fixed is None else []
        videos = [ep.meta["sequence"] for ep in test]
        raw = [score_estimates(ep.y[None], ep.truth) for ep in test]
        raw_auc = [float(s["success_auc"][0]) for s in raw]
        summary[detector] = {"raw_success_auc": float(np.mean(raw_auc)), "raw_worst": worst(raw_auc, videos),
                             "missing_fraction": float(np.mean([ep.meta["n_missing"] / len(ep.y) for ep in test]))}
        for backend in args.backends:
            tuner = fixed
            if tuner is None:
                tuner, train_auc = grid_tune(train, backend, points=args.grid)
                tuned_files[f"tuned/{detector}-{backend}.json"] = json_text(tuner.document(
                    detector=detector, train_success_auc=train_auc, train_videos=[ep.meta["sequence"] for ep in train]))
            auc: dict[str, list[float]] = {m: [] for m in METHODS}
            for ep, raw_scores in zip(test, raw, strict=False):
                for method, params in (("rule", ep.nominal.as_params()), ("tuned", tuner.params(ep))):
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
                               "delta_ci95": paired_mean_ci(diff, rng), "worst": worst(auc[method], videos)}
            res["tuned"]["action"] = tuner.act(test[0]).tolist()
            summary[detector][backend] = res
            print(f"{detector:9s} {backend:9s} raw {np.mean(auc['raw']):.3f}  rule {res['rule']['success_auc']:.3f}"
                  f"  tuned {res['tuned']['success_auc']:.3f}", flush=True)
    header = ("video", "detector", "backend", "method", "success_auc", "precision20", "rmse", "n_missing")
    shown = {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()}
    text = table(summary, args.backends, args)
    try:
        publish_folder(args.out, {"results.csv": csv_text(header, rows), "table.md": text,
                                  "summary.json": json_text({"args": shown, "detectors": summary}), **tuned_files})
    except ValueError as err:  # another run filled --out meanwhile
        print(f"video_table.py: error: --out {err}; nothing written", file=sys.stderr)
        return 1
    print(text)
    return 0


def _row(ep, detector: str, backend: str, method: str, scores: dict) -> tuple:
    return (ep.meta["sequence"], detector, backend, method, float(scores["success_auc"][0]),
            float(scores["precision20"][0]), float(scores["rmse"][0]), ep.meta["n_missing"])


def table(summary: dict, backends: list[str], args: argparse.Namespace) -> str:
    """Markdown: mean success AUC per detector (filtered cells show Δ vs raw and its 95 % CI), then each
    detector's worst video per method (lowest AUC and which test video)."""
    methods = [f"{m} {b}" for b in backends for m in ("rule", "tuned")]
    head = ["detector", "raw AUC", "missing %", *methods]
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
    lines.append(note + "; cells: mean AUC (Δ vs raw [95 % bootstrap CI over videos]).\n")
    head = ["detector", "raw", *methods]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for detector, s in summary.items():
        cells = [detector, _worst_cell(s["raw_worst"])]
        cells += [_worst_cell(s[b][m]["worst"]) for b in backends for m in ("rule", "tuned")]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append(f"\nWorst video per detector and method: the lowest success AUC of the {args.n_test} test videos "
                 "(and which video).")
    return "\n".join(lines) + "\n"


def _worst_cell(w: dict) -> str:
    return f"{w['success_auc']:.3f} ({w['video']})"

