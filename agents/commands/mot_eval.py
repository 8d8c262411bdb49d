"""Score box filters on real detection streams: MOT15 identities, public detections matched to the ground truth.

    python scripts/mot_eval.py --mot-root ../shared/data/mot15 --split test --out runs/mot_eval
    python scripts/mot_eval.py --split test --model runs/ppo_kf_cmn_mot_s0 --pretrained otb_kf_cmn --out runs/mot_eval

Every method runs causally on each identity's detection stream (:mod:`bboxtune.envs.episodes.mot_source`: from its first
to its last matched detection) and is scored by :mod:`bboxtune.agents.evaluation.mot_eval`: mean IoU on the detected frames (from
the fifth after the first detection on), IoU inside the detection gaps (pooled over frames; a method without an
estimate there scores 0), log(RMSE_raw / RMSE) on the detected frames; paired differences to the raw detections
and to ByteTrack's Kalman filter, 95 % intervals resampling identities. Methods: ``raw``; the filters practitioners
ship, ``bytetrack_kf`` (ByteTrack / DeepSORT, stock weights) and ``sort_kf``; the fixed N_opt rule on ``kf``,
``kf_cmn`` and ``ufir_cmn``; ``bytetrack_oracle`` (ByteTrack's two std weights chosen per identity with the
ground truth from a 6 × 5 grid: the headroom of tuning them, not a method); each ``--model`` run directory and
``--pretrained`` tuner (:class:`bboxtune.agents.smoothing.tuner.Tuner`, which sees the detections only). Each
``--gap-decay VELOCITY SIZE`` adds ByteTrack's filter with that gap policy (``gap_velocity_decay``, ``gap_size_decay``
per second of gap: :mod:`bboxtune.filters.gap_output`), stock weights otherwise, and every tuner of ``bytetrack_kf``
with that policy instead of its own ``backend_params``.

Writes ``summary.md`` (the table and the command), ``per_identity.csv`` (every method's scores per identity) and
``command.txt`` into ``--out`` (created; an existing folder must not hold these files), each atomically.
A bad flag, folder or data file ends the run with exit status 2 and one line naming it.
"""

from __future__ import annotations

import itertools
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from bboxtune import filters
from bboxtune.agents.cli import ArgumentParser, command, command_line, existing_dir, out_dir, outputs_taken
from bboxtune.agents.evaluation import mot_eval
from bboxtune.agents.evaluation.video_tables import csv_text
from bboxtune.agents.smoothing.tuner import Tuner, load_pretrained
from bboxtune.envs.data import mot
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.episodes.config import SPLITS, EnvConfig
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.mot_source import identity_episode, identity_name
from bboxtune.filters.bytetrack_kf import GAP_DECAYS

OUTPUTS = ("summary.md", "per_identity.csv", "command.txt")
REFERENCES = ("raw", "bytetrack_kf")
# ByteTrack's std weights, relative to the stock 1/20 (position) and 1/160 (velocity): the oracle's 6 × 5 grid
ORACLE_POSITION = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
ORACLE_VELOCITY = (0.25, 0.5, 1.0, 2.0, 4.0)
STOCK = {"std_weight_position": 1 / 20, "std_weight_velocity": 1 / 160}


def tuner_method(tuner: Tuner) -> mot_eval.Method:
    """A learned tuner: each identity's detections smoothed with the parameters it chooses from them."""
    def run(episodes: list[Episode]) -> list[np.ndarray]:
        return [xywh_to_cxcywh(tuner.smooth(cxcywh_to_xywh(ep.y), ep.tau)) for ep in episodes]
    return run


def bytetrack_oracle(episodes: list[Episode]) -> list[np.ndarray]:
    """ByteTrack's filter with the grid pair of std weights that maximises each identity's mean IoU over its
    detected and gap frames, chosen with the ground truth (a headroom reference)."""
    best: list[tuple[float, np.ndarray]] = [(-np.inf, ep.y) for ep in episodes]
    for p, v in itertools.product(ORACLE_POSITION, ORACLE_VELOCITY):
        params = {"std_weight_position": STOCK["std_weight_position"] * p,
                  "std_weight_velocity": STOCK["std_weight_velocity"] * v}
        for i, (ep, est) in enumerate(zip(episodes, mot_eval.backend_method("bytetrack_kf", params)(episodes), strict=False)):
            sets = mot_eval.frame_sets(ep)
            scored = sets.detected | sets.gaps
            value = float(mot_eval.box_iou(est, ep.truth)[scored].mean()) if scored.any() else 0.0
            if value > best[i][0]:
                best[i] = (value, est)
    return [est for _, est in best]


def gap_policy(decays: tuple[float, float]) -> dict[str, float]:
    """bytetrack_kf's gap policy of one ``--gap-decay VELOCITY SIZE``."""
    return dict(zip(GAP_DECAYS, decays, strict=True))


def methods(models: list[Path], pretrained: list[str],
            gap_decays: Sequence[tuple[float, float]] = ()) -> dict[str, mot_eval.Method]:
    """Every method of the module docstring, by name (tuners loaded here, so a bad one fails before scoring)."""
    out: dict[str, mot_eval.Method] = {
        "raw": mot_eval.raw_method,
        "bytetrack_kf": mot_eval.backend_method("bytetrack_kf"),
        "sort_kf": mot_eval.backend_method("sort_kf"),
        **{f"rule_{b}": mot_eval.rule_method(b) for b in ("kf", "kf_cmn", "ufir_cmn")},
        "bytetrack_oracle": bytetrack_oracle,
    }
    for decays in gap_decays:
        try:
            filters.make("bytetrack_kf", filters.constant_velocity(1.0, ndim=4), **gap_policy(decays))
        except ValueError as err:
            raise ValueError(f"--gap-decay: {err}") from None
        out[f"bytetrack_kf gap{decays}"] = mot_eval.backend_method("bytetrack_kf", gap_policy(decays))
    tuners = {f"model:{run_dir.name}": Tuner.from_run(run_dir) for run_dir in models}
    for name in pretrained:
        try:
            tuners[f"pretrained:{name}"] = load_pretrained(name)
        except ValueError as err:  # an unknown name: the message lists the installed ones
            raise ValueError(f"--pretrained: {err}") from None
    for name, tuner in tuners.items():
        out[name] = tuner_method(tuner)
        if tuner.backend == "bytetrack_kf":
            out |= {f"{name} gap{d}": tuner_method(tuner.with_backend_params(gap_policy(d))) for d in gap_decays}
    return out


def markdown_table(columns: list[str], rows: list[dict[str, str]]) -> list[str]:
    """Markdown lines of ``rows`` (of :func:`bboxtune.agents.evaluation.mot_eval.paired_rows`) in ``columns``."""
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns),
            *("| " + " | ".join(row[c] for c in columns) + " |" for row in rows)]


def summary_text(rows: list[dict[str, str]], title: str, n: int, sequences: list[str], command: str) -> str:
    """summary.md: the table of :func:`bboxtune.agents.evaluation.mot_eval.paired_rows` and what it was measured on."""
    lines = [f"# Filters on MOT15 detection streams: {title}", "",
             f"{n} identities of {', '.join(sequences)}; 95 % intervals resample identities "
             f"({mot_eval.N_BOOT} resamples).", "", "```", command, "```", "", *markdown_table(list(rows[0]), rows)]
    return "\n".join(lines) + "\n"


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="mot_eval.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--mot-root", default=None, type=existing_dir, help="MOT15 data folder (default: $MOT_ROOT)")
    parser.add_argument("--split", choices=SPLITS, default="test", help="which sequences (default: test)")
    parser.add_argument("--model", action="append", default=[], type=existing_dir, metavar="RUN_DIR",
                        help="a scripts/train.py run directory to score (repeatable)")
    parser.add_argument("--pretrained", action="append", default=[], metavar="NAME",
                        help="a pretrained tuner to score (repeatable; bboxtune.agents.smoothing.pretrained)")
    parser.add_argument("--gap-decay", action="append", default=[], nargs=2, type=float, metavar=("VELOCITY", "SIZE"),
                        help="add ByteTrack's filter (and every bytetrack_kf tuner) with this gap policy: the decays "
                             "per second of gap of the centre's and the size's rates, each in [0, 1] (repeatable)")
    parser.add_argument("--out", required=True, type=out_dir, help="output folder (created)")
    args = parser.parse_args(argv)
    if outputs_taken(args.out, OUTPUTS):
        return 2
    command = command_line("mot_eval", argv)
    try:
        scored = methods(args.model, args.pretrained, [(v, size) for v, size in args.gap_decay])
        identities = mot.split(mot.load_identities(args.mot_root))[args.split]
        if not identities:
            raise ValueError(f"no MOT identities in split {args.split!r}")
        cfg = EnvConfig(source="mot")
        episodes = [identity_episode(cfg, identity) for identity in identities]
        scores = {name: mot_eval.score_method(method, episodes) for name, method in scored.items()}
    except (ValueError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    rows = mot_eval.paired_rows(scores, REFERENCES)
    header = ["method", "identity", *next(iter(scores.values()))]
    table = [[name, identity_name(identity), *(float(s[k][i]) for k in header[2:])]
             for name, s in scores.items() for i, identity in enumerate(identities)]
    os.makedirs(args.out, exist_ok=True)
    sequences = sorted({i.sequence for i in identities})
    write_text_atomic(args.out / "per_identity.csv", csv_text(header, table))
    write_text_atomic(args.out / "command.txt", command + "\n")
    text = summary_text(rows, f"split {args.split!r}", len(identities), sequences, command)
    write_text_atomic(args.out / "summary.md", text)
    print(text, end="")
    return 0
