"""Sweep train.py settings on Ray Tune (the optional extra bboxtune[ray]), each trial scored on the val split.

    python scripts/sweep.py --out runs/sweep --backends ufir_cmn kf_cmn --seeds 0 1 2 --hyperparams learning_rate:3e-4,1e-3
    python scripts/sweep.py --out runs/sweep --resume            # continue an interrupted sweep (the same flags)
    python scripts/sweep.py --out runs/sweep_smoke --smoke       # two tiny trials, seconds
    python scripts/sweep.py --out runs/sweep --address auto ...  # the same sweep on a running Ray cluster

The grid is the product of --algos × --backends × --sources × the --hyperparams values × --seeds; a trial runs
scripts/train.py and then scripts/compare.py --split val on its run (bboxtune.agents.training.sweep: the folder layout, resuming,
the aggregate). Local by default (a new Ray instance with this machine's CPU count, or --cpus); --address auto or
ray://host:port joins a cluster (ray:// needs the extra ray[client]). --out must be new or empty (or, with --resume,
the sweep to continue). Writes OUT/sweep.json, OUT/trials/<trial>/ (run/, compare/, trial.csv) and
OUT/aggregate.csv / aggregate.md (per setting: seeds, mean / min / max of the val log-ratio, gap closed and win
rate), then prints the aggregate.

Before Ray starts, every flag and every trial's setting is checked in this process: each --hyperparams value (a
finite number or a YAML value, each once) and, per setting of the grid, train.py's own checks (the key against
agents/hyperparams/<algo>.yml and the algorithm's constructor, the envs built, the model built without training);
--cpus-per-trial at most the local CPUs (a cluster's, once joined; --address auto with none running is refused).
A bad flag or setting: one line naming it, exit status 2, nothing written (sweep.json is written once Ray is up).

--resume reads no pickle: it rebuilds the trial list from OUT/sweep.json (checked against the flags), keeps every
trial with a trials/<trial>/trial.csv and runs the others (a trial whose run has a checkpoint continues it with
train.py --resume). --trust-pickle makes it restore Ray Tune's own experiment state instead (OUT/ray/sweep/tuner.pkl,
a pickle, which can run code when loaded: only for sweep folders you trust).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import os
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import yaml

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
from bboxtune.agents.commands import train
from bboxtune.agents.training import run_checks
from bboxtune.agents.training.algos import ALGOS
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import check_free
from bboxtune.agents.training.sweep import SweepSpec, resume_state, run_sweep, train_argv
from bboxtune.envs.data.number_grammar import parse_float, parse_int, shorten
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.config import SOURCES

GRID_FLAGS = ("--algos", "--backends", "--sources", "--seeds", "--hyperparams", "--timesteps")  # what --smoke sets
MAX_NAME = 200  # bytes of a trial's folder name (file systems allow 255)
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
    p.add_argument("--address", default=None,
                   help="a Ray cluster: 'auto' ($RAY_ADDRESS, else the one this machine runs) or ray://host:port (needs "
                        "ray[client]); default: a new local Ray instance ($RAY_ADDRESS is not read)")
    p.add_argument("--cpus", type=positive_int, default=None, help="CPUs of the local Ray (default: this machine's)")
    p.add_argument("--cpus-per-trial", type=float_range(0.01), default=1.0,
                   help="CPUs a trial reserves: at most the CPUs Ray has (local: --cpus or this machine's)")
    p.add_argument("--resume", action="store_true",
                   help="continue the sweep in --out from its sweep.json and trial.csv files (finished trials are kept)")
    p.add_argument("--trust-pickle", action="store_true",
                   help="with --resume: restore Ray Tune's pickled experiment state OUT/ray/sweep/tuner.pkl instead "
                        "(pickles can run code: only for sweep folders you trust)")
    p.add_argument("--smoke", action="store_true",
                   help="two tiny trials (ppo, ufir_cmn, sim, seeds 0 and 1; no grid flags with it)")
    return p


def spec_of(p: ArgumentParser, args: argparse.Namespace, tokens: list[str]) -> SweepSpec:
    """The sweep the flags describe (``tokens``: the command line, to tell given flags from defaults)."""
    if args.smoke:
        given = sorted({t.split("=", 1)[0] for t in tokens} & set(GRID_FLAGS))
        if given:
            p.error(f"{' '.join(given)} cannot be given with --smoke (it sets the grid: {' '.join(GRID_FLAGS)})")
        return SMOKE
    try:
        grid = {key: _values(key, value)
                for key, value in key_values("--hyperparams", args.hyperparams, separators=":").items()}
    except ValueError as err:
        p.error(str(err))
    if len(set(args.seeds)) != len(args.seeds):
        p.error(f"--seeds {args.seeds}: a seed twice")
    return SweepSpec(algos=tuple(args.algos), backends=tuple(args.backends), sources=tuple(args.sources),
                     seeds=tuple(args.seeds), grid=grid, timesteps=args.timesteps)


def _values(key: str, value: Any) -> list[Any]:
    """The swept values of ``--hyperparams KEY:VALUE`` (``value`` as YAML read it): comma-separated ones of a
    string, each a finite number or a YAML value (as train.py --hyperparams reads it); ValueError naming the key."""
    values = [_value(key, v.strip()) for v in value.split(",")] if isinstance(value, str) else [value]
    if any(values.count(v) > 1 for v in values):  # also 1 and 1.0
        raise ValueError(f"--hyperparams {key}: a value twice in {shorten(str(value))}")
    try:
        json.dumps(values, allow_nan=False)
    except (TypeError, ValueError):
        raise ValueError(f"--hyperparams {key}: {shorten(str(value))}; allowed: finite numbers, strings, booleans "
                         "and lists / mappings of them (JSON values, for sweep.json)") from None
    return values


def _value(key: str, text: str) -> Any:
    """One swept value: an integer or finite number (the project's number grammar), else a YAML value."""
    if not text:
        raise ValueError(f"--hyperparams {key}: an empty value; allowed: comma-separated values")
    with contextlib.suppress(ValueError):
        return parse_int(text)
    try:
        return parse_float(text)
    except ValueError as err:
        try:
            float(text)
        except ValueError:
            pass
        else:  # a number to Python but not to the grammar: nan, inf, 1_0, non-ASCII digits
            raise ValueError(f"--hyperparams {key}: {err}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        raise ValueError(f"--hyperparams {key}: {shorten(text)} is not a YAML value") from None


def check_flags(p: ArgumentParser, args: argparse.Namespace) -> None:
    """The flags that need no file: --trust-pickle, --address / --cpus, --cpus-per-trial, Ray (and its client)."""
    if args.trust_pickle and not args.resume:
        p.error("--trust-pickle applies to --resume only (a new sweep reads no pickles)")
    if args.address is not None:
        host = args.address.removeprefix("ray://")
        if args.address != "auto" and (host == args.address or not host.rpartition(":")[0]
                                       or not host.rpartition(":")[2].isdigit()):
            p.error(f"--address {shorten(args.address)}: allowed: 'auto' or ray://HOST:PORT")
        if args.cpus is not None:
            p.error("--cpus applies to a local Ray only (a cluster has its own CPUs); drop it or --address")
    cpus = args.cpus or os.cpu_count() or 1
    if args.address is None and args.cpus_per_trial > cpus:
        p.error(f"--cpus-per-trial {args.cpus_per_trial:g}: more than the {cpus} CPUs of the local Ray "
                f"({'--cpus' if args.cpus else 'this machine'}); allowed: 0.01..{cpus}")
    try:
        import ray  # noqa: F401  (the optional extra)
    except ImportError:
        p.error("Ray is not installed: pip install -e '.[ray]' (the optional extra bboxtune[ray])")
    if (args.address or "").startswith("ray://") and importlib.util.find_spec("grpc") is None:  # what ray[client] adds
        p.error(f"--address {shorten(args.address)}: a ray:// address needs Ray Client: pip install 'ray[client]'")


def check_trials(spec: SweepSpec, trials: list[dict[str, Any]], out: Path) -> None:
    """The trial names (folders of ``out/trials``), and each setting of ``trials`` (its first seed) through
    train.py's own checks, in this process and without training; :class:`RunError` naming the trial otherwise."""
    names = Counter(t["name"] for t in spec.trials())
    for name, count in names.items():
        if len(name.encode()) > MAX_NAME or count > 1:
            raise RunError(f"--hyperparams: trial name {shorten(name)} is {'not unique' if count > 1 else 'too long'} (a "
                           f"folder of {out / 'trials'}); allowed: distinct names of at most {MAX_NAME} bytes")
    seen = set()
    for trial in trials:
        setting = json.dumps([trial[k] for k in ("algo", "backend", "source", "hyperparams")], sort_keys=True)
        if setting in seen:
            continue
        seen.add(setting)
        try:
            args = _train_args(train_argv(spec, trial, out / "trials" / trial["name"] / "run"))
            cfg = train.new_config(args)
            hp = run_checks.hyperparams_of(cfg, "--hyperparams")
            run_checks.check_tensorboard(cfg)
            venv = run_checks.validated_envs(cfg, hp, "--algos / --backends / --sources", "--hyperparams")
            try:
                run_checks.check_new_model(cfg, hp, venv, f"--hyperparams / agents/hyperparams/{cfg['algo']}.yml")
            finally:
                venv.close()
        except RunError as err:
            raise RunError(f"trial {trial['name']}: {err}") from None


def _train_args(argv: list[str]) -> argparse.Namespace:
    """train.py's parsed command line ``argv``; its one-line error as :class:`RunError`."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            return train.parse_args(argv)
    except SystemExit:
        line = err.getvalue().strip().removesuffix(" (see --help)").replace(": error:", ":", 1)
        raise RunError(line or f"train.py refused {argv}") from None


def run(argv: list[str] | None = None) -> Path:
    """Run (or resume) the sweep the command line ``argv`` describes; returns its output folder."""
    p = build_parser()
    tokens = list(sys.argv[1:] if argv is None else argv)
    args = p.parse_args(tokens)
    spec = spec_of(p, args, tokens)
    check_flags(p, args)
    out = Path(args.out)
    try:
        if args.resume:
            done = resume_state(spec, out.resolve())
        else:
            check_free(out, "choose another --out, or pass --resume to continue the sweep there")
            done = set()
        check_trials(spec, [t for t in spec.trials() if t["name"] not in done], out.resolve())
        table = run_sweep(spec, out, address=args.address, cpus=args.cpus, cpus_per_trial=args.cpus_per_trial,
                          resume=args.resume, trust_pickle=args.trust_pickle)
    except RunError as err:
        p.error(str(err))
    print((out / "aggregate.md").read_text())
    print(f"{len(table)} setting(s); wrote {args.out}")
    return out


@command
def main(argv: list[str] | None = None) -> int:
    """The command line: :func:`run`; exit status 0 (a bad argument exits 2 with one line)."""
    run(argv)
    return 0
