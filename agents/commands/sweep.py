"""Sweep train.py settings on Ray Tune (the optional extra bboxtune[ray]), each trial scored on the val split.

    python scripts/sweep.py --out runs/sweep --backends ufir_cmn kf_cmn --seeds 0 1 2 --hyperparams learning_rate:3e-4,1e-3
    python scripts/sweep.py --out runs/sweep --resume            # continue an interrupted sweep (the same flags)
    python scripts/sweep.py --out runs/sweep_smoke --smoke       # two tiny trials, seconds
    python scripts/sweep.py --out runs/sweep --address auto ...  # the same sweep on a running Ray cluster

The grid is the product of --algos × --backends × --sources × the --hyperparams values × --seeds; a trial runs
scripts/train.py and then scripts/compare.py --split val on its run (bboxtune.agents.training.sweep: the folder layout, resuming,
the aggregate). Local by default (ray.init() with this machine's CPU count, or --cpus); --address joins a
cluster. --out must be new or empty (or, with --resume, the sweep to continue). Writes OUT/trials/<trial>/
(run/, compare/, trial.csv) and OUT/aggregate.csv / aggregate.md (per setting: seeds, mean / min / max of the val
log-ratio, gap closed and win rate), then prints the aggregate. Bad flags: one line, exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from bboxtune.agents.cli import (
    ArgumentParser,
    HelpFormatter,
    command,
    float_range,
    key_values,
    nonnegative_int,
    out_dir,
    positive_int,
)
from bboxtune.agents.training.algos import ALGOS
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import check_free
from bboxtune.agents.training.sweep import SweepSpec, run_sweep
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.config import SOURCES

SMOKE = SweepSpec(seeds=(0, 1), timesteps=128,
                  train_args=("--hyperparams", "n_envs:8", "n_steps:8", "batch_size:32", "--env-kwargs", "track_length=100",
                              "--eval-freq", "64", "--eval-episodes", "4", "--checkpoint-freq", "64"),
                  compare_args=("--episodes", "4", "--train-episodes", "11", "--global-trials", "4",
                                "--oracle-budget", "16", "--bootstrap", "50"))


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="sweep.py", description=__doc__, formatter_class=HelpFormatter, allow_abbrev=False)
    p.add_argument("--out", type=out_dir, required=True, help="sweep folder: new or empty (with --resume: the sweep's)")
    p.add_argument("--algos", nargs="+", choices=sorted(ALGOS), default=["ppo"])
    p.add_argument("--backends", nargs="+", choices=BACKENDS, default=["ufir_cmn"])
    p.add_argument("--sources", nargs="+", choices=SOURCES, default=["sim"])
    p.add_argument("--seeds", nargs="+", type=nonnegative_int, default=[0, 1, 2])
    p.add_argument("--hyperparams", nargs="*", default=[], metavar="KEY:V1,V2",
                   help="hyperparameter values to sweep (YAML values, comma-separated), e.g. learning_rate:3e-4,1e-3")
    p.add_argument("--timesteps", type=positive_int, default=None, help="train.py --timesteps of every trial")
    p.add_argument("--address", default=None, help="a Ray cluster: 'auto' or ray://host:port (default: local)")
    p.add_argument("--cpus", type=positive_int, default=None, help="local CPUs for Ray (default: this machine's)")
    p.add_argument("--cpus-per-trial", type=float_range(0.01), default=1.0, help="CPUs a trial reserves")
    p.add_argument("--resume", action="store_true", help="continue the sweep in --out (finished trials are kept)")
    p.add_argument("--smoke", action="store_true", help="two tiny trials (ppo, ufir_cmn, sim, seeds 0 and 1)")
    return p


def spec_of(p: ArgumentParser, args: argparse.Namespace) -> SweepSpec:
    if args.smoke:
        return SMOKE
    try:
        pairs = key_values("--hyperparams", args.hyperparams, separators=":")
    except ValueError as err:
        p.error(str(err))
    grid = {}
    for key, value in pairs.items():
        values = [v.strip() for v in str(value).split(",")] if isinstance(value, str) else [value]
        if not all(values):
            p.error(f"--hyperparams {key}: empty value in {value!r}; allowed: comma-separated values")
        grid[key] = [_scalar(v) for v in values]
    if len(set(args.seeds)) != len(args.seeds):
        p.error(f"--seeds {args.seeds}: a seed twice")
    return SweepSpec(algos=tuple(args.algos), backends=tuple(args.backends), sources=tuple(args.sources),
                     seeds=tuple(args.seeds), grid=grid, timesteps=args.timesteps)


def _scalar(text: object) -> object:
    """A swept value: int, float or str (as train.py --hyperparams reads it)."""
    for kind in (int, float):
        try:
            return kind(text)  # type: ignore[call-overload, arg-type]  # any value: int()/float() raise for one they refuse
        except (TypeError, ValueError):
            pass
    return text


def run(argv: list[str] | None = None) -> Path:
    """Run (or resume) the sweep the command line ``argv`` describes; returns its output folder."""
    p = build_parser()
    args = p.parse_args(argv)
    spec = spec_of(p, args)
    try:
        if not args.resume:
            check_free(args.out, "choose another --out, or pass --resume to continue the sweep there")
        import ray  # noqa: F401  (the optional extra)
    except ImportError:
        p.error("Ray is not installed: pip install -e '.[ray]' (the optional extra bboxtune[ray])")
    except RunError as err:
        p.error(str(err))
    try:
        table = run_sweep(spec, Path(args.out), address=args.address, cpus=args.cpus,
                          cpus_per_trial=args.cpus_per_trial, resume=args.resume)
    except RunError as err:
        p.error(str(err))
    print((Path(args.out) / "aggregate.md").read_text())
    print(f"{len(table)} setting(s); wrote {args.out}")
    return Path(args.out)


@command
def main(argv: list[str] | None = None) -> int:
    """The command line: :func:`run`; exit status 0 (a bad argument exits 2 with one line)."""
    run(argv)
    return 0
