"""Sweeps on Ray Tune: a grid of algorithm × back end × source × hyperparameters × seeds, one trial per point.

A trial is ``scripts/train.py`` (the training function, as a subprocess of the Ray worker: the run directory, its
checkpoints and lock as for any run) followed by ``scripts/compare.py`` on the **val** split (the test split stays
unseen while choosing settings). It reports ``val_log_ratio`` (the trained model's mean log(RMSE_rule / RMSE)),
``val_gap_closed`` (its share of the rule → oracle gap) and ``val_win_rate`` to Tune. Layout of ``OUT``::

    sweep.json                 the sweep's settings (the grid, the flags); a resume checks it is the same sweep
    ray/                       Ray Tune's experiment state (read back only by a resume with ``trust_pickle``)
    trials/<trial>/run/        the train.py run directory;   trials/<trial>/compare/  compare.py on val
    trials/<trial>/trial.csv   one row: the trial's settings and metrics
    aggregate.csv / aggregate.md   one row per setting (all but the seed): seeds, mean / min / max of the metrics

Resuming reads no pickle: the trial list is rebuilt from ``sweep.json`` (:func:`read_spec`, a JSON file checked
field by field), a trial with a ``trial.csv`` (:func:`finished_trials`, checked against the trial) is kept and the
others run again, a trial whose run directory holds a checkpoint continuing it with ``train.py --resume``. Ray
Tune's own restore (``Tuner.restore`` of ``ray/sweep``, which unpickles ``tuner.pkl`` and can run code) is used
only with ``trust_pickle``. Local by default (a new ``ray.init(address="local")`` with ``cpus`` CPUs, this
machine's by default); ``address="auto"`` or ``"ray://host:port"`` joins a cluster, whose nodes need this
repository at the same path with the package installed (``pip install -e '.[ray]'``). Ray is an optional extra
(``bboxtune[ray]``): it is imported by the functions that need it.
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
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from bboxtune.agents.training.run_files import RunError, read_json
from bboxtune.envs.data import textfile
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.data.number_grammar import shorten

REPO = Path(__file__).resolve().parents[2]
METRICS = ("val_log_ratio", "val_gap_closed", "val_win_rate")
SETTINGS = ("algo", "backend", "source", "hyperparams")  # what a setting is (a trial adds its seed)
TRIAL_COLUMNS = ("name", "algo", "backend", "source", "seed", "hyperparams", *METRICS)  # trial.csv
_LISTS = {"algos": str, "backends": str, "sources": str, "seeds": int, "train_args": str, "compare_args": str}


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
        """Every point of the grid, as Tune's ``param_space`` entries (names without ``/`` or spaces; sweep.py
        refuses a grid whose names repeat or are too long for a folder)."""
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


def read_spec(path: Path) -> SweepSpec:
    """The sweep ``sweep.json`` at ``path`` describes, parsed as JSON and checked field by field (a file that was
    sent or edited is input like any other); :class:`RunError` naming ``path`` and the field."""
    doc = read_json(path)
    names = sorted(f.name for f in fields(SweepSpec))
    spec = doc.get("spec") if isinstance(doc, dict) and list(doc) == ["spec"] else None
    if not isinstance(spec, dict) or sorted(spec) != names:
        raise RunError(f"{path}: not a sweep's settings; expected {{\"spec\": {{...}}}} with exactly the keys {names}")
    for key, kind in _LISTS.items():
        value = spec[key]
        if not isinstance(value, list) or not all(isinstance(v, kind) and not isinstance(v, bool) for v in value):
            raise RunError(f"{path}: spec.{key} = {shorten(json.dumps(value))}; expected a list of {kind.__name__}")
    if not spec["algos"] or not spec["backends"] or not spec["sources"] or not spec["seeds"] or min(spec["seeds"]) < 0:
        raise RunError(f"{path}: spec.algos, backends, sources and seeds must not be empty (seeds: integers >= 0)")
    grid, steps = spec["grid"], spec["timesteps"]
    if not isinstance(grid, dict) or not all(isinstance(v, list) and v for v in grid.values()):
        raise RunError(f"{path}: spec.grid = {shorten(json.dumps(grid))}; expected an object of non-empty lists")
    if steps is not None and (not isinstance(steps, int) or isinstance(steps, bool) or steps < 1):
        raise RunError(f"{path}: spec.timesteps = {shorten(json.dumps(steps))}; expected null or an integer >= 1")
    return SweepSpec(algos=tuple(spec["algos"]), backends=tuple(spec["backends"]), sources=tuple(spec["sources"]),
                     seeds=tuple(spec["seeds"]), grid=grid, timesteps=steps, train_args=tuple(spec["train_args"]),
                     compare_args=tuple(spec["compare_args"]))


def write_spec(spec: SweepSpec, path: Path) -> None:
    """``spec`` as ``sweep.json`` (atomically): what :func:`read_spec` reads back."""
    write_text_atomic(path, json.dumps({"spec": asdict(spec)}, indent=2, allow_nan=False) + "\n")


def read_trial(path: Path, trial: dict[str, Any] | None = None) -> dict[str, str]:
    """The one row of the ``trial.csv`` at ``path``: the columns :data:`TRIAL_COLUMNS`, numbers in the metric
    columns and, given ``trial``, the settings of that trial; :class:`RunError` naming ``path`` otherwise."""
    try:
        rows = list(csv.DictReader(io.StringIO(textfile.read_text(path), newline="")))
    except (ValueError, csv.Error) as err:
        raise RunError(f"{path}: not a readable trial.csv ({err})") from None
    if len(rows) != 1 or tuple(rows[0]) != TRIAL_COLUMNS or None in rows[0].values():
        raise RunError(f"{path}: expected a header {','.join(TRIAL_COLUMNS)} and one row of as many cells")
    row = rows[0]
    try:
        for metric in METRICS:
            float(row[metric])
    except ValueError:
        raise RunError(f"{path}: {', '.join(METRICS)} must be numbers; got {[row[m] for m in METRICS]}") from None
    if trial is not None:
        want = {**{k: str(trial[k]) for k in ("name", "algo", "backend", "source", "seed")},
                "hyperparams": json.dumps(trial["hyperparams"], sort_keys=True)}
        if {k: row[k] for k in want} != want:
            raise RunError(f"{path}: the results of another trial (expected {want}); remove the file to run the trial again")
    return row


def finished_trials(spec: SweepSpec, out: Path) -> set[str]:
    """The names of the trials of ``spec`` with a ``trial.csv`` in ``out/trials`` (each checked by :func:`read_trial`)."""
    done = set()
    for trial in spec.trials():
        path = out / "trials" / trial["name"] / "trial.csv"
        if path.exists():
            read_trial(path, trial)
            done.add(trial["name"])
    return done


def train_argv(spec: SweepSpec, trial: dict[str, Any], run: Path) -> list[str]:
    """The train.py flags of a new run of ``trial`` in the run directory ``run``."""
    hyper = [f"{k}:{json.dumps(v)}" for k, v in trial["hyperparams"].items()]
    return ["--algo", trial["algo"], "--backend", trial["backend"], "--source", trial["source"], "--seed", str(trial["seed"]),
            "--out", str(run), *(["--timesteps", str(spec.timesteps)] if spec.timesteps else []),
            *(["--hyperparams", *hyper] if hyper else []), *spec.train_args]


def trial_commands(spec: SweepSpec, trial: dict[str, Any], folder: Path) -> tuple[list[str], list[str]]:
    """The train.py and compare.py command lines of ``trial`` writing into ``folder`` (a run directory with a
    checkpoint is resumed, not restarted)."""
    run, compare = folder / "run", folder / "compare"
    py = sys.executable
    if (run / "checkpoints" / "latest").exists():
        train = [py, str(REPO / "scripts/train.py"), "--resume", str(run)]
    else:
        train = [py, str(REPO / "scripts/train.py"), *train_argv(spec, trial, run)]
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
    row = {**{k: trial[k] for k in TRIAL_COLUMNS[:5]}, "hyperparams": json.dumps(trial["hyperparams"], sort_keys=True),
           **metrics}
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
    trials = [read_trial(path) for path in sorted((out / "trials").glob("*/trial.csv"))]
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


def resume_state(spec: SweepSpec, out: Path) -> set[str]:
    """Check that ``out`` holds the sweep ``spec`` (its ``sweep.json``, :func:`read_spec`) and return the names of
    its finished trials (:func:`finished_trials`); :class:`RunError` naming the file otherwise."""
    saved = out / "sweep.json"
    if not saved.is_file():
        raise RunError(f"{out}: no sweep.json (nothing to resume)")
    if read_spec(saved) != spec:
        raise RunError(f"{saved}: another sweep's settings; resume with the same flags or choose another --out")
    return finished_trials(spec, out)


def run_sweep(spec: SweepSpec, out: Path, *, address: str | None = None, cpus: int | None = None,
              cpus_per_trial: float = 1.0, resume: bool = False, trust_pickle: bool = False) -> list[dict[str, Any]]:
    """Run (or, with ``resume``, continue) the sweep ``spec`` into ``out`` and aggregate it.

    ``sweep.json`` is written once Ray is up, so a refused address or CPU count leaves ``out`` untouched. A resume
    (:func:`resume_state`) runs the trials without a ``trial.csv`` (all finished: Ray is not started); with
    ``trust_pickle`` it restores Ray Tune's saved experiment instead, where there is one."""
    out = out.resolve()
    done = resume_state(spec, out) if resume else set()
    pending = [t for t in spec.trials() if t["name"] not in done]
    if pending:
        _tune(spec, out, pending, trust_pickle, address=address, cpus=cpus, cpus_per_trial=cpus_per_trial, new=not resume)
    return aggregate(out)


def _tune(spec: SweepSpec, out: Path, trials: list[dict[str, Any]], restore: bool, *, address: str | None,
          cpus: int | None, cpus_per_trial: float, new: bool) -> None:
    """Start (or join) Ray, write ``sweep.json`` if ``new``, and run ``trials`` (or restore the saved experiment)."""
    import ray
    from ray import tune

    os.environ.setdefault("RAY_CHDIR_TO_TRIAL_DIR", "0")
    try:  # "local": a new instance even where RAY_ADDRESS or a running one would otherwise be joined
        ray.init(address=address or "local", num_cpus=None if address else (cpus or os.cpu_count()),
                 include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
    except (ConnectionError, RuntimeError, ValueError) as err:
        where = f"--address {address}: cannot join the Ray cluster" if address else "Ray cannot start here"
        raise RunError(f"{where} ({' '.join(str(err).split())})") from None
    try:
        have = float(ray.cluster_resources().get("CPU", 0))
        if cpus_per_trial > have:
            raise RunError(f"--cpus-per-trial {cpus_per_trial:g}: Ray has {have:g} CPUs"
                           f"{f' (the cluster at {address})' if address else ''}; allowed: 0.01..{have:g}")
        if new:
            out.mkdir(parents=True, exist_ok=True)
            write_spec(spec, out / "sweep.json")
        trainable = tune.with_resources(run_trial, {"cpu": cpus_per_trial})
        if restore and tune.Tuner.can_restore(str(out / "ray" / "sweep")):  # vouched for: tuner.pkl is a pickle
            tuner = tune.Tuner.restore(str(out / "ray" / "sweep"), trainable, resume_errored=True, restart_errored=False)
        else:
            space = {"spec": asdict(spec), "out": str(out), "trial": tune.grid_search(trials)}
            tuner = tune.Tuner(trainable, param_space=space, run_config=tune.RunConfig(
                name="sweep", storage_path=str(out / "ray"), verbose=0))
        results = tuner.fit()
    finally:
        ray.shutdown()
    errors = [str(err) for err in (results[i].error for i in range(len(results))) if err]  # a ResultGrid: len, [i]
    if errors:
        try:
            aggregate(out)
            others = f"the others are aggregated in {out / 'aggregate.md'}"
        except RunError:
            others = "none finished"
        raise RunError(f"{len(errors)} trial(s) failed ({others}): {errors[0]}")
