"""The trained runs a comparison scores (``scripts/compare.py --model``): one run's final and best models, or several
runs of one algorithm and env that differ only in their training seed, each checked against the evaluation env
(:func:`bboxtune.agents.training.safe_load.check_env_match`), named for the report and grouped per seed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym

from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import SB3Policy, load_config
from bboxtune.agents.training.safe_load import check_env_match


def load_learned(run: Path, cfg: dict[str, Any], env: gym.Env, trust_pickle: bool, suffix: str = "") -> list[SB3Policy]:
    """The run's final model and, if the run has one, its best-on-validation model (``<algo>_best``), named with
    ``suffix``, each checked against the evaluation env ``env``."""
    learned = [SB3Policy.load(run, "final", trust_pickle=trust_pickle)]
    if (run / "best_model.zip").exists():
        learned.append(SB3Policy.load(run, "best", trust_pickle=trust_pickle))
    for policy, prefix in zip(learned, ("", "best_"), strict=False):
        policy.name = f"{cfg['algo']}{'_best' if prefix else ''}{suffix}"
        check_env_match(run / f"{prefix}model.zip", policy.model, cfg, env)
    return learned


def load_seed_runs(runs: list[Path], cfg: dict[str, Any], env: gym.Env, trust_pickle: bool
                   ) -> tuple[list[SB3Policy], dict[str, list[str]]]:
    """Several runs of one FilterTune-v0 env (training seeds): their models named ``<algo>[_best]_s<seed>`` and
    the groups to aggregate ({``<algo>``: names, ``<algo>_best``: names if every run has a best model})."""
    learned: list[SB3Policy] = []
    seeds: dict[int, Path] = {}
    for run in runs:
        other = load_config(run)
        if (other["env_id"], other["env_kwargs"], other["algo"]) != (cfg["env_id"], cfg["env_kwargs"], cfg["algo"]):
            raise RunError(f"{run}: {other['algo']} on {other['env_id']} {other['env_kwargs']}; several --model must be "
                           f"runs of one algorithm and env ({runs[0]}: {cfg['algo']} on {cfg['env_id']} {cfg['env_kwargs']})")
        if other["seed"] in seeds:
            raise RunError(f"{run}: seed {other['seed']} again (also {seeds[other['seed']]}); several --model need distinct "
                           "seeds")
        seeds[other["seed"]] = run
        learned += load_learned(run, other, env, trust_pickle, suffix=f"_s{other['seed']}")
    algo = cfg["algo"]
    groups = {name: [p.name for p in learned if p.name.rsplit("_s", 1)[0] == name] for name in (algo, f"{algo}_best")}
    return learned, {k: v for k, v in groups.items() if len(v) == len(runs)}


def describe_models(run: Path | None, runs: list[Path], learned: list[SB3Policy], cfg: dict[str, Any]) -> str:
    """The settings line of the scored model(s)."""
    if not runs:
        return "none (no --model: the re-tuning baselines and window regressors only)"
    if len(runs) == 1:
        return f"`{run}` ({learned[0].model.num_timesteps} timesteps, seed {cfg['seed']})"
    return ", ".join(f"`{r}`" for r in runs) + " (one per training seed)"
