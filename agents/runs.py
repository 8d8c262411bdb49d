"""Training-run directories: vectorised envs of a split, atomic checkpoints, and loading a trained tuner.

A run directory written by ``scripts/train.py`` holds::

    config.yml            every setting of the run (arguments, env kwargs, hyperparameters, versions)
    command.txt           the command line that started it (and each resume, appended)
    model.zip             the final model;          vecnormalize.pkl       its VecNormalize statistics
    best_model.zip        best on the val split;    best_vecnormalize.pkl  the statistics at that time
    evaluations.npz       EvalCallback log (val split); eval_curve.csv the same as text
    train_log.csv         reward of every training episode;   learning_curve.png
    checkpoints/latest    name of the newest complete checkpoint folder, checkpoints/ckpt_<timesteps>/

A checkpoint folder is written under a temporary name and renamed when complete, then ``latest`` is
replaced atomically (``os.replace``), so a run killed at any moment resumes from a complete checkpoint.
"""

from __future__ import annotations

import argparse

import json
import os
import shutil
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

import envs  # noqa: F401  (registers the env ids)
from agents.algos import algo_class
from agents.baselines import ObsPolicy
from agents.splits import SplitSeeds

CHECKPOINTS = "checkpoints"
LATEST = "latest"


def make_env(env_id: str, env_kwargs: dict[str, Any], split: str = "test") -> gym.Env:
    """One env of ``env_id`` whose resets are pinned to ``split`` (:class:`agents.splits.SplitSeeds`; the
    env's own ``split=`` picks the OTB sequences)."""
    return SplitSeeds(gym.make(env_id, **{**env_kwargs, "split": split}), split=split)


def make_vec(env_id: str, env_kwargs: dict[str, Any], *, split: str, n_envs: int, seed: int,
             vec_env: str = "dummy", cycle: int = 100) -> VecEnv:
    """``n_envs`` Monitor-wrapped envs of ``split`` (noise seeds of that split, the env's ``split=`` for OTB
    sequences; reset seeds ``seed + rank``), Dummy- or SubprocVecEnv."""
    cls = SubprocVecEnv if vec_env == "subproc" else DummyVecEnv
    return make_vec_env(partial(_registered_make, env_id), n_envs=n_envs, seed=seed, env_kwargs={**env_kwargs, "split": split}, vec_env_cls=cls,
                        wrapper_class=SplitSeeds, wrapper_kwargs={"split": split, "cycle": cycle})


def _registered_make(env_id: str, **kwargs: Any) -> gym.Env:
    """``gym.make`` after ``import envs`` (SubprocVecEnv workers may not have imported it yet)."""
    import envs  # noqa: F401

    return gym.make(env_id, **kwargs)


def _atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    write(tmp)
    os.replace(tmp, path)


def write_text_atomic(path: Path, text: str) -> None:
    _atomic_write(path, lambda p: p.write_text(text))


def save_checkpoint(run_dir: Path, model: BaseAlgorithm, state: dict[str, Any], keep: int = 2) -> Path:
    """Write ``checkpoints/ckpt_<num_timesteps>/`` (model, VecNormalize, replay buffer of off-policy
    algorithms, ``state.json``) under a temporary name, rename it, point ``latest`` at it, and delete all
    but the ``keep`` newest checkpoints. Returns the checkpoint folder."""
    root = Path(run_dir) / CHECKPOINTS
    root.mkdir(parents=True, exist_ok=True)
    name = f"ckpt_{model.num_timesteps:012d}"
    final, tmp = root / name, root / (name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    model.save(tmp / "model.zip")
    venv = model.get_vec_normalize_env()
    if venv is not None:
        venv.save(tmp / "vecnormalize.pkl")
    if hasattr(model, "replay_buffer") and model.replay_buffer is not None:
        model.save_replay_buffer(tmp / "replay_buffer.pkl")
    (tmp / "state.json").write_text(json.dumps({"num_timesteps": int(model.num_timesteps), **state}))
    shutil.rmtree(final, ignore_errors=True)
    os.replace(tmp, final)
    write_text_atomic(root / LATEST, name)
    for old in sorted(p for p in root.glob("ckpt_*") if p.is_dir() and not p.name.endswith(".tmp"))[:-keep]:
        if old != final:
            shutil.rmtree(old, ignore_errors=True)
    return final


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The newest complete checkpoint folder of ``run_dir`` (None if there is none)."""
    pointer = Path(run_dir) / CHECKPOINTS / LATEST
    if not pointer.exists():
        return None
    folder = pointer.parent / pointer.read_text().strip()
    if not (folder / "model.zip").exists():
        raise ValueError(f"{pointer} names {folder.name}, which has no model.zip")
    return folder


def load_config(run_dir: Path) -> dict[str, Any]:
    path = Path(run_dir) / "config.yml"
    if not path.exists():
        raise ValueError(f"{run_dir} is not a train.py run directory: no config.yml")
    return yaml.safe_load(path.read_text())


class SB3Policy(ObsPolicy):
    """A trained SB3 tuner: VecNormalize's observation statistics, then the deterministic policy."""

    def __init__(self, model: BaseAlgorithm, normalizer: VecNormalize | None, name: str) -> None:
        self.model = model
        self.normalizer = normalizer
        self.name = name

    def predict(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if self.normalizer is not None:
            obs = self.normalizer.normalize_obs(obs)
        actions, _ = self.model.predict(obs, deterministic=True)
        return np.asarray(actions, dtype=np.float64).reshape(len(obs), -1)

    @classmethod
    def load(cls, run_dir: Path, which: str = "final") -> SB3Policy:
        """The ``"final"`` (``model.zip``) or ``"best"`` (``best_model.zip``, best on the val split) tuner."""
        if which not in ("final", "best"):
            raise ValueError(f"which={which!r}; allowed: 'final', 'best'")
        run_dir = Path(run_dir)
        cfg = load_config(run_dir)
        prefix = "" if which == "final" else "best_"
        model_path = run_dir / f"{prefix}model.zip"
        if not model_path.exists():
            raise ValueError(f"{model_path} not found (is the run finished? resume it with train.py --resume {run_dir})")
        model = algo_class(cfg["algo"]).load(model_path, device="cpu")
        norm_path = run_dir / f"{prefix}vecnormalize.pkl"
        normalizer = None
        if norm_path.exists():
            dummy = DummyVecEnv([lambda: gym.make(cfg["env_id"], **cfg["env_kwargs"])])
            normalizer = VecNormalize.load(str(norm_path), dummy)
            normalizer.training, normalizer.norm_reward = False, False
        return cls(model, normalizer, name=cfg["algo"])


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Shows the module docstring as written and appends real defaults (not None/False/empty) to the help."""

    def _get_help_string(self, action: argparse.Action) -> str:
        default = action.default
        shown = not (default is None or default is False or default == [] or default == argparse.SUPPRESS)
        if action.help and shown and "%(default)" not in action.help:
            return action.help + " (default: %(default)s)"
        return action.help or ""
