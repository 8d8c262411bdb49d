"""Leave-one-sequence-out (LOSO) evaluation of learned tuners on real detection streams: every MOT15 identity scored
by tuners that never saw its sequence.

    python scripts/mot_loso.py --mot-root ../shared/data/mot15 --runs runs/mot_loso --out runs/mot_loso_table

The fixed split tests on one sequence (KITTI-13: 15 identities); this protocol tests on all of them. For each fold
(a sequence held out, ``--folds``; default every sequence of the data):

1. Train: for every ``--backend`` and ``--seeds`` seed, ``scripts/train.py --source mot --reward success_auc
   --timesteps T --n-envs 16 --env-kwargs otb_speedup_max=3 mot_holdout=<fold>`` (the recipe of the fixed split's
   tuners, ``docs/results/mot15/commands.txt``) into ``--runs``/<fold>/<backend>_s<seed>; the fold's other sequences
   are its training identities (``bboxtune.envs.data.mot.holdout_split``). The final model is scored (nothing is
   selected on the held-out sequence). A run folder that already holds a finished run of the same settings is reused;
   one that holds anything else (other settings, an unfinished run) is refused.
2. Select, on the training identities only (every frame): ByteTrack's gap policy (:data:`GAP_GRID`, the grid of
   ``docs/mot15.md``'s val selection) with the highest pooled gap IoU, once for the stock weights and once for each
   ``bytetrack_kf`` tuner (ties: the first in grid order, which starts with (1, 1) = no policy).
3. Score the held-out identities (:mod:`bboxtune.agents.evaluation.mot_eval`): ``raw``, ``bytetrack_kf``, ``sort_kf``,
   the rules ``rule_kf`` / ``rule_kf_cmn`` / ``rule_ufir_cmn``, ``bytetrack_kf +gap`` (stock weights, the fold's
   policy), each tuner ``<backend> s<seed>`` and, for ``bytetrack_kf`` tuners, ``<backend> s<seed> +gap``.

The table pools every fold's identities: paired differences to ``raw`` and ``bytetrack_kf`` with 95 % intervals
resampling identities; a second table gives the differences with intervals resampling the sequences (coarse: six
clusters). Writes ``summary.md`` (both tables, the per-fold differences against stock ByteTrack and the chosen
policies), ``per_identity.csv``, ``folds.csv`` and ``command.txt`` into ``--out`` (an existing folder must not
hold them), each atomically, after every fold is done. Bad input: one line, exit status 2.
"""

from __future__ import annotations

import itertools
import os
import sys
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from bboxtune.agents.cli import (
    ArgumentParser,
    HelpFormatter,
    command,
    command_line,
    existing_dir,
    nonnegative_int,
    out_dir,
    outputs_taken,
    positive_int,
)
from bboxtune.agents.commands import train
from bboxtune.agents.commands.mot_eval import REFERENCES, gap_policy, markdown_table, summary_text, tuner_method
from bboxtune.agents.evaluation import mot_eval
from bboxtune.agents.evaluation.video_tables import csv_text
from bboxtune.agents.smoothing.tuner import Tuner
from bboxtune.agents.training.runs import load_config
from bboxtune.envs.data import mot
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.mot_source import identity_episode, identity_name

OUTPUTS = ("summary.md", "per_identity.csv", "folds.csv", "command.txt")
# ByteTrack's gap policies (gap_velocity_decay, gap_size_decay), (1, 1) = none first: docs/mot15.md's val grid
GAP_GRID: tuple[tuple[float, float], ...] = tuple(itertools.product((1.0, 0.7, 0.5, 0.3, 0.1, 0.0), (1.0, 0.5, 0.0)))
DEFAULT_BACKENDS = ("bytetrack_kf", "kf_cmn", "ufir_cmn")
# folds.csv: fold, method, identities, gap frames, ΔIoU detected and gaps vs stock ByteTrack, gap policy ("v s" or "")
FoldRow = tuple[str, str, int, int, float, float, str]
FOLD_HEADER = ["fold", "method", "identities", "gap_frames", "d_iou_detected_vs_bytetrack_kf",
               "d_iou_gaps_vs_bytetrack_kf", "gap_policy"]
TRAIN_ENV_KWARGS = ("otb_speedup_max=3",)


def pooled_gap_iou(scores: Mapping[str, np.ndarray]) -> float:
    """IoU inside gaps pooled over the frames of several identities (0 without a gap frame)."""
    return float(scores["iou_gap_sum"].sum() / max(scores["n_gap"].sum(), 1.0))


def best_gap_policy(method_of: Mapping[tuple[float, float], mot_eval.Method], episodes: list[Episode]) -> tuple[float, float]:
    """The gap policy whose method scores the highest pooled gap IoU on ``episodes`` (ties: the first)."""
    values = {decays: pooled_gap_iou(mot_eval.score_method(method, episodes)) for decays, method in method_of.items()}
    return max(values, key=lambda d: (values[d], -list(values).index(d)))


def train_argv(backend: str, seed: int, fold: str, timesteps: int, mot_root: Path | None, run_dir: Path) -> list[str]:
    """scripts/train.py's command line of one fold's tuner (module docstring, step 1)."""
    kwargs = [*TRAIN_ENV_KWARGS, f"mot_holdout={fold}", *([f"mot_root={mot_root}"] if mot_root else [])]
    return ["--backend", backend, "--source", "mot", "--reward", "success_auc", "--timesteps", str(timesteps),
            "--n-envs", "16", "--seed", str(seed), "--eval-freq", str(timesteps), "--eval-episodes", "64",
            "--env-kwargs", *kwargs, "--out", str(run_dir)]


def trained(argv: list[str], run_dir: Path) -> Path:
    """The run of ``argv`` in ``run_dir``: reused if it holds a finished run of the same settings, else trained
    (ValueError if it holds anything else)."""
    if run_dir.is_dir() and any(run_dir.iterdir()) and not (run_dir / "model.zip").exists():
        raise ValueError(f"{run_dir}: holds an unfinished run (no model.zip); remove it or give another --runs folder")
    if (run_dir / "model.zip").exists():
        expected = train.new_config(train.parse_args(argv))
        found = load_config(run_dir)
        keys = ("env_kwargs", "seed", "total_timesteps", "algo")
        if {k: found.get(k) for k in keys} != {k: expected[k] for k in keys}:
            raise ValueError(f"{run_dir}: holds a run of other settings ({train.CONFIG}); give another --runs folder")
        return run_dir
    return train.run(argv)


def fold_methods(fold: str, tuners: Mapping[str, Tuner], train_episodes: list[Episode]) -> tuple[dict[str, mot_eval.Method],
                                                                                                dict[str, tuple[float, float]]]:
    """The scored methods of one fold (module docstring, step 3) and the gap policy chosen for each (step 2)."""
    methods: dict[str, mot_eval.Method] = {
        "raw": mot_eval.raw_method,
        "bytetrack_kf": mot_eval.backend_method("bytetrack_kf"),
        "sort_kf": mot_eval.backend_method("sort_kf"),
        **{f"rule_{b}": mot_eval.rule_method(b) for b in ("kf", "kf_cmn", "ufir_cmn")},
    }
    chosen = {"bytetrack_kf +gap": best_gap_policy(
        {d: mot_eval.backend_method("bytetrack_kf", gap_policy(d)) for d in GAP_GRID}, train_episodes)}
    methods["bytetrack_kf +gap"] = mot_eval.backend_method("bytetrack_kf", gap_policy(chosen["bytetrack_kf +gap"]))
    for name, tuner in tuners.items():
        methods[name] = tuner_method(tuner)
        if tuner.backend == "bytetrack_kf":
            with_policy = {d: tuner.with_backend_params(gap_policy(d)) for d in GAP_GRID}
            chosen[f"{name} +gap"] = best_gap_policy({d: tuner_method(t) for d, t in with_policy.items()}, train_episodes)
            methods[f"{name} +gap"] = tuner_method(with_policy[chosen[f"{name} +gap"]])
    print(f"fold {fold}: gap policies chosen on the training identities {chosen}", file=sys.stderr)
    return methods, chosen


def fold_rows(fold: str, scores: Mapping[str, Mapping[str, np.ndarray]],
              chosen: Mapping[str, tuple[float, float]]) -> list[FoldRow]:
    """folds.csv rows of one fold: per method, the held-out identities and gap frames, the differences to stock
    ByteTrack (mean IoU on detected frames, pooled IoU in gaps) and the chosen gap policy."""
    stock = scores["bytetrack_kf"]
    rows = []
    for name, s in scores.items():
        ok = np.isfinite(s["iou_detected"]) & np.isfinite(stock["iou_detected"])
        d_det = float(np.mean(s["iou_detected"][ok] - stock["iou_detected"][ok])) if ok.any() else float("nan")
        policy = chosen.get(name)
        rows.append((fold, name, len(s["n_gap"]), int(s["n_gap"].sum()), d_det, pooled_gap_iou(s) - pooled_gap_iou(stock),
                     "" if policy is None else f"{policy[0]:g} {policy[1]:g}"))
    return rows


def fold_table(rows: list[FoldRow]) -> list[str]:
    """Markdown: ΔIoU vs stock ByteTrack (detected / gaps) of every method per fold, and the chosen gap policies."""
    folds = list(dict.fromkeys(r[0] for r in rows))
    names = list(dict.fromkeys(r[1] for r in rows))
    by = {(r[0], r[1]): r for r in rows}
    lines = ["| method | " + " | ".join(f"{f} ({by[(f, 'raw')][2]} id., {by[(f, 'raw')][3]} gap fr.)" for f in folds) + " |",
             "|" + "---|" * (len(folds) + 1)]
    for name in names:
        cells = []
        for f in folds:
            r = by[(f, name)]
            cells.append(f"{r[4]:+.3f} / {r[5]:+.3f}" + (f" ({r[6]})" if r[6] else ""))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="mot_loso.py", description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument("--mot-root", default=None, type=existing_dir, help="MOT15 data folder (default: $MOT_ROOT)")
    parser.add_argument("--folds", nargs="+", default=None, metavar="SEQUENCE",
                        help="the sequences to hold out, one fold each (default: every sequence of the data)")
    parser.add_argument("--backend", action="append", default=None, choices=BACKENDS,
                        help=f"a back end to train tuners of (repeatable; default: {' '.join(DEFAULT_BACKENDS)})")
    parser.add_argument("--seeds", nargs="+", type=nonnegative_int, default=[0, 1, 2], help="training seeds")
    parser.add_argument("--timesteps", type=positive_int, default=12288, help="training episodes per tuner")
    parser.add_argument("--runs", required=True, type=out_dir,
                        help="folder of the training runs (<fold>/<backend>_s<seed>; finished runs of the same "
                             "settings are reused)")
    parser.add_argument("--out", required=True, type=out_dir, help="output folder (created)")
    args = parser.parse_args(argv)
    for flag, values in (("--folds", args.folds or []), ("--backend", args.backend or []), ("--seeds", args.seeds)):
        if len(set(values)) < len(values):
            parser.error(f"argument {flag}: {values} repeats a value; give each once")
    if outputs_taken(args.out, OUTPUTS):
        return 2
    backends = args.backend or list(DEFAULT_BACKENDS)
    command_text = command_line("mot_loso", argv)
    try:
        identities = mot.load_identities(args.mot_root)
        sequences = sorted({i.sequence for i in identities})
        folds = args.folds or sequences
        for fold in folds:
            mot.holdout_split(identities, fold)  # an unknown sequence fails before any training
        cfg = EnvConfig(source="mot")
        scores: dict[str, dict[str, list[np.ndarray]]] = {}
        names: list[str] = []
        rows: list[FoldRow] = []
        for fold in folds:
            parts = mot.holdout_split(identities, fold)
            tuners = {}
            for backend, seed in itertools.product(backends, args.seeds):
                run_dir = args.runs / fold / f"{backend}_s{seed}"
                argv_of_run = train_argv(backend, seed, fold, args.timesteps, args.mot_root, run_dir)
                tuners[f"{backend} s{seed}"] = Tuner.from_run(trained(argv_of_run, run_dir))
            methods, chosen = fold_methods(fold, tuners, [identity_episode(cfg, i) for i in parts["train"]])
            held_out = [identity_episode(cfg, i) for i in parts["test"]]
            fold_scores = {name: mot_eval.score_method(method, held_out) for name, method in methods.items()}
            rows += fold_rows(fold, fold_scores, chosen)
            names += [identity_name(i) for i in parts["test"]]
            for name, s in fold_scores.items():
                for key, values in s.items():
                    scores.setdefault(name, {}).setdefault(key, []).append(values)
    except (ValueError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    pooled = {name: {k: np.concatenate(v) for k, v in s.items()} for name, s in scores.items()}
    table = mot_eval.paired_rows(pooled, REFERENCES)
    header = ["method", "identity", *next(iter(pooled.values()))]
    per_identity = [[name, identity, *(float(s[k][i]) for k in header[2:])]
                    for name, s in pooled.items() for i, identity in enumerate(names)]
    text = summary_text(table, "leave-one-sequence-out, each identity scored by tuners that never saw its sequence",
                        len(names), list(folds), command_text)
    by_sequence = mot_eval.paired_rows(pooled, REFERENCES, clusters=[n.split("/")[0] for n in names])
    columns = ["method", *(c for c in by_sequence[0] if c.startswith("d_"))]
    text += (f"\n## The differences with intervals that resample the {len(folds)} sequences instead (coarse: few "
             "clusters)\n\n" + "\n".join(markdown_table(columns, by_sequence)) +
             "\n\n## Per fold: ΔIoU vs stock ByteTrack, detected frames / gaps (gap policy chosen on the fold's "
             "training identities)\n\n" + "\n".join(fold_table(rows)) + "\n")
    os.makedirs(args.out, exist_ok=True)
    write_text_atomic(args.out / "per_identity.csv", csv_text(header, per_identity))
    write_text_atomic(args.out / "folds.csv", csv_text(FOLD_HEADER, rows))
    write_text_atomic(args.out / "command.txt", command_text + "\n")
    write_text_atomic(args.out / "summary.md", text)
    print(text, end="")
    return 0
