"""Sweeps on Ray Tune: a grid of algorithm × back end × source × hyperparameters × seeds, one trial per point.

A trial is ``scripts/train.py`` (the training function, as a subprocess of the Ray worker: the run directory, its
checkpoints and lock as for any run) followed by ``scripts/compare.py`` on the **val** split (the test split stays
unseen while choosing settings). It reports ``val_log_ratio`` (the trained model's mean log(RMSE_rule / RMSE)),
``val_gap_closed`` (its share of the rule → oracle gap) and ``val_win_rate`` to Tune. Layout of ``OUT``::

    sweep.json                 the sweep's settings (the grid, the flags); a resume checks it is the same sweep
    ray/                       Ray Tune's experiment state (``Tuner.restore`` resumes from it)
    trials/<trial>/run/        the train.py run directory;   trials/<trial>/compare/  compare.py on val
    trials/<trial>/trial.csv   one row: the trial's settings and metrics
    aggregate.csv / aggregate.md   one row per setting (all but the seed): seeds, mean / min / max of the metrics

Resuming (``--resume``): finished trials are kept, errored and unfinished ones run again; a trial whose run
directory holds a checkpoint continues it with ``train.py --resume`` instead of starting over. Local by default
(``ray.init()`` on this machine with its CPU count); ``address="auto"`` or ``"ray://host:port"`` joins a cluster,
whose nodes need this repository at the same path with the package installed (``pip install -e '.[ray]'``).
Ray is an optional extra (``bboxtune[ray]``): it is imported by the functions that need it.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import os
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bboxtune.agents.training.run_files import RunError
from bboxtune.envs.data.atomic_files import write_text_atomic

REPO = Path(__file__).resolve().parents[2]
METRICS = ("val_log_ratio", "val_gap_closed", "val_win_rate")
SETTINGS = ("algo", "backend", "source", "hyperparams")  # what a setting is (a trial adds its seed)


@dataclass(frozen=True)
class SweepSpec:
    """The grid and the per-trial flags of a sweep (``sweep.json``)."""

    algos: tuple[str, ...] = ("ppo",)
    backends: tuple[str, ...] = ("ufir_cmn",)
    sources: tuple[str, ...] = ("sim",)
    seeds: tuple[int, ...] = (0, 1, 2)
    grid: dict[str, list[Any]] = field(default_factory=dict)  # hyperparameter -> values (train.py --hyperparams)
    timesteps: int | None = None  # None: the YAML's n_timesteps
    train_args: tuple[str, ...] = ()  # more train.py flags for every trial
    compare_args: tuple[str, ...] = ()  # more compare.py flags for every trial (besides --split val)

    def trials(self) -> list[dict[str, Any]]:
        """Every point of the grid, as Tune's ``param_space`` entries (names are unique and file-safe)."""
        keys = sorted(self.grid)
        points = []
        for algo, backend, source, values, seed in itertools.product(
                self.algos, self.backends, self.sources, itertools.product(*(self.grid[k] for k in keys)), self.seeds):
            hyper = dict(zip(keys, values, strict=False))
            tag = "_".join(f"{k}-{v}" for k, v in hyper.items())
            name = "_".join(p for p in (algo, backend, source, tag, f"s{seed}") if p)
            points.append({"name": name.replace("/", "-").replace(" ", ""), "algo": algo, "backend": backend,
                           "source": source, "hyperparams": hyper, "seed": seed})
        return points


def trial_commands(spec: SweepSpec, trial: dict[str, Any], folder: Path) -> tuple[list[str], list[str]]:
    """The train.py and compare.py command lines of ``trial`` writing into ``folder`` (a run directory with a
    checkpoint is resumed, not restarted)."""
    run, compare = folder / "run", folder / "compare"
    py = sys.executable
    if (run / "checkpoints" / "latest").exists():
        train = [py, str(REPO / "scripts/train.py"), "--resume", str(run)]
    else:
        hyper = [f"{k}:{json.dumps(v)}" for k, v in trial["hyperparams"].items()]
        train = [py, str(REPO / "scripts/train.py"), "--algo", trial["algo"], "--backend", trial["backend"],
                 "--source", trial["source"], "--seed", str(trial["seed"]), "--out", str(run),
                 *(["--timesteps", str(spec.timesteps)] if spec.timesteps else []),
                 *(["--hyperparams", *hyper] if hyper else []), *spec.train_args]
    return train, [py, str(REPO / "scripts/compare.py"), "--model", str(run), "--split", "val", "--out", str(compare),
                   *spec.compare_args]


def val_metrics(compare: Path, algo: str) -> dict[str, float]:
    """The trained model's mean log-ratio, gap closed and win rate vs the rule in ``compare/results.csv``."""
    with open(compare / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    mine = {r["episode"]: float(r["log_ratio"]) for r in rows if r["method"] == algo}
    oracle = np.mean([float(r["log_ratio"]) for r in rows if r["method"] == "oracle"])
    ratio = np.array(list(mine.values()))
    return {"val_log_ratio": float(ratio.mean()), "val_gap_closed": float(ratio.mean() / oracle) if oracle else float("nan"),
            "val_win_rate": float(np.mean((ratio > 0) + 0.5 * (ratio == 0)))}


def run_trial(config: dict[str, Any]) -> dict[str, float]:
    """Tune's function trainable: train, score on val, write ``trial.csv``, report the metrics."""
    from ray import tune

    fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) and k != "grid" else v for k, v in config["spec"].items()}
    spec = SweepSpec(**fields)
    trial = config["trial"]
    folder = Path(config["out"]) / "trials" / trial["name"]
    folder.mkdir(parents=True, exist_ok=True)
    for cmd, log, done in zip(trial_commands(spec, trial, folder), ("train.log", "compare.log"),
                              (folder / "run" / "model.zip", folder / "compare" / "results.csv"), strict=False):
        if done.exists():
            continue  # trained / scored before an interruption
        with open(folder / log, "w") as fh:
            code = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=REPO).returncode
        if code != 0:
            raise RuntimeError(f"{' '.join(cmd)} exited {code}; see {folder / log}")
    metrics = val_metrics(folder / "compare", trial["algo"])
    row = {**{k: trial[k] for k in ("name", "algo", "backend", "source", "seed")},
           "hyperparams": json.dumps(trial["hyperparams"], sort_keys=True), **metrics}
    write_csv(folder / "trial.csv", [row])
    tune.report(metrics)
    return metrics


def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """``rows`` (equal keys) as a CSV file, written atomically."""
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(path, text.getvalue())


def aggregate(out: Path) -> list[dict[str, Any]]:
    """Every finished trial's ``trial.csv`` grouped by setting (all but the seed): ``aggregate.csv`` and
    ``aggregate.md`` in ``out`` (seeds, mean / min / max of each metric), best mean val log-ratio first."""
    trials = []
    for path in sorted((out / "trials").glob("*/trial.csv")):
        with open(path, newline="") as fh:
            trials += list(csv.DictReader(fh))
    if not trials:
        raise RunError(f"{out}: no finished trial (trials/*/trial.csv)")
    groups: dict[tuple, list[dict[str, str]]] = {}
    for t in trials:
        groups.setdefault(tuple(t[k] for k in SETTINGS), []).append(t)
    table = []
    for key, members in groups.items():
        row: dict[str, Any] = dict(zip(SETTINGS, key, strict=False))
        row["seeds"] = " ".join(sorted((m["seed"] for m in members), key=int))
        for metric in METRICS:
            v = np.array([float(m[metric]) for m in members])
            row.update({f"{metric}_mean": float(v.mean()), f"{metric}_min": float(v.min()), f"{metric}_max": float(v.max())})
        table.append(row)
    table.sort(key=lambda r: -r["val_log_ratio_mean"])
    write_csv(out / "aggregate.csv", table)
    md = ["| " + " | ".join([*SETTINGS, "seeds", *(f"{m} mean [min, max]" for m in METRICS)]) + " |",
          "|" + "---|" * (len(SETTINGS) + 1 + len(METRICS))]
    for r in table:
        cells = [r[k] for k in SETTINGS] + [r["seeds"]] + [
            f"{r[f'{m}_mean']:+.3f} [{r[f'{m}_min']:+.3f}, {r[f'{m}_max']:+.3f}]" for m in METRICS]
        md.append("| " + " | ".join(str(c) for c in cells) + " |")
    write_text_atomic(out / "aggregate.md", f"# Sweep {out}: val split, one row per setting\n\n" + "\n".join(md) + "\n")
    return table


def run_sweep(spec: SweepSpec, out: Path, *, address: str | None = None, cpus: int | None = None,
              cpus_per_trial: float = 1.0, resume: bool = False) -> list[dict[str, Any]]:
    """Run (or, with ``resume``, continue) the sweep ``spec`` into ``out`` and aggregate it."""
    import ray
    from ray import tune

    out = out.resolve()
    settings = {"spec": asdict(spec)}
    saved = out / "sweep.json"
    if resume:
        if not saved.is_file():
            raise RunError(f"{out}: no sweep.json (nothing to resume)")
        if json.loads(saved.read_text()) != json.loads(json.dumps(settings)):
            raise RunError(f"{saved}: another sweep's settings; resume with the same flags or choose another --out")
    else:
        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(saved, json.dumps(settings, indent=2) + "\n")
    os.environ.setdefault("RAY_CHDIR_TO_TRIAL_DIR", "0")
    ray.init(address=address, num_cpus=None if address else (cpus or os.cpu_count()), include_dashboard=False,
             log_to_driver=False, ignore_reinit_error=True)
    try:
        trainable = tune.with_resources(run_trial, {"cpu": cpus_per_trial})
        if resume and tune.Tuner.can_restore(str(out / "ray" / "sweep")):
            tuner = tune.Tuner.restore(str(out / "ray" / "sweep"), trainable, resume_errored=True, restart_errored=False)
        else:
            space = {"spec": settings["spec"], "out": str(out), "trial": tune.grid_search(spec.trials())}
            tuner = tune.Tuner(trainable, param_space=space, run_config=tune.RunConfig(
                name="sweep", storage_path=str(out / "ray"), verbose=0))
        results = tuner.fit()
    finally:
        ray.shutdown()
    errors = [str(err) for err in (results[i].error for i in range(len(results))) if err]  # a ResultGrid: len, [i]
    table = aggregate(out)
    if errors:
        raise RunError(f"{len(errors)} trial(s) failed (the others are aggregated in {out / 'aggregate.md'}): {errors[0]}")
    return table
