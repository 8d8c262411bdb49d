"""Filter parameters for video episodes: the fixed rule (``ep.nominal.as_params()``), a grid-searched fixed action,
or a trained tuner — policies of the one tuner hierarchy (:mod:`bboxtune.agents.policies.baselines`) bound to a back end
(:class:`EpisodeTuner`).

Actions follow the env's mapping (:class:`bboxtune.envs.episodes.actions.ActionMap`, default ``tune`` of the back end), so
a tuned action means the same thing relative to every episode's nominal σ as it does in the env.

* :func:`grid_tune` — one action for a whole video set: the point of a regular grid over [-1, 1]^d with the
  best mean score over *training* episodes (no test data); saved/loaded as JSON (:meth:`EpisodeTuner.document`).
* :func:`load_tuner` — a ``tuned.json`` from :func:`grid_tune` or a ``scripts/train.py`` run directory
  (``config.yml`` + ``model.zip`` [+ ``vecnormalize.json``], loaded by ``bboxtune.agents.training.runs.SB3Policy``): the policy
  sees the env's observation features of each episode (:func:`bboxtune.envs.episodes.features.measurement_features`) and its
  back end and ``tune`` come from the run's ``env_kwargs``.
"""

from __future__ import annotations

import itertools
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bboxtune.agents.policies.baselines import GlobalPolicy, ObsPolicy
from bboxtune.agents.training.runs import SB3Policy, load_config
from bboxtune.envs.data import textfile
from bboxtune.envs.episodes.actions import DEFAULT_TUNE, K_AXIS, ActionMap
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.features import measurement_features
from bboxtune.envs.episodes.scoring import run_positions, score_estimates


def action_map(backend: str, tune: Sequence[str] | None = None, horizon_max: int = 400,
               sigma_decades: float = 1.5) -> ActionMap:
    """The env's action mapping for ``backend`` (defaults as :class:`bboxtune.envs.episodes.config.EnvConfig`)."""
    return ActionMap(tune=tuple(tune or DEFAULT_TUNE[backend]), K=K_AXIS, horizon_max=horizon_max,
                     sigma_decades=sigma_decades)


@dataclass(frozen=True)
class EpisodeTuner:
    """A policy of the baselines' hierarchy bound to a back end and its action map, acting on video episodes: a
    fixed action (:class:`bboxtune.agents.policies.baselines.GlobalPolicy`, e.g. from :func:`grid_tune`) or a trained model
    (:class:`bboxtune.agents.training.runs.SB3Policy`). It sees what the env shows the agent: the observation features of the
    episode's measurements (:func:`bboxtune.envs.episodes.features.measurement_features`, with the fixed rule's run)."""

    policy: ObsPolicy
    backend: str
    actions: ActionMap
    msd: bool = False  # the observation has the "msd" feature set's extra entry (EnvConfig.features)

    def act(self, ep: Episode) -> np.ndarray:
        """Action (d,) in [-1, 1] for episode ``ep`` (a fixed action needs no observation: no filter run)."""
        if isinstance(self.policy, GlobalPolicy):
            return self.policy.action
        rule = run_positions(self.backend, ep.y, ep.tau, ep.nominal.as_params())[0]
        obs = measurement_features(ep.y, ep.tau, ep.nominal.sigma_v, ep.nominal.sigma_w, rule, msd=self.msd)
        return self.actions.check(self.policy.predict(obs[None]))[0]

    def params(self, ep: Episode) -> dict[str, np.ndarray]:
        """Physical parameters (arrays (1,)) for ``ep``."""
        return self.actions.to_params(self.act(ep), ep.nominal)

    def document(self, **info: Any) -> dict[str, Any]:
        """A fixed tuner as the JSON object :func:`load_tuner` reads: ``{"backend", "tune", "horizon_max",
        "sigma_decades", "action", **info}``."""
        if not isinstance(self.policy, GlobalPolicy):
            raise TypeError(f"only a fixed action (GlobalPolicy) is saved as tuned.json, not a {type(self.policy).__name__}")
        a = self.actions
        return {"backend": self.backend, "tune": list(a.tune), "horizon_max": a.horizon_max,
                "sigma_decades": a.sigma_decades, "action": self.policy.action.tolist(), **info}


def fixed_tuner(backend: str, action: np.ndarray, actions: ActionMap | None = None) -> EpisodeTuner:
    """The same action (d,) for every episode of ``backend`` (checked to lie in [-1, 1])."""
    amap = actions or action_map(backend)
    return EpisodeTuner(GlobalPolicy(amap.check(action)[0]), backend, amap)


def grid_tune(episodes: Sequence[Episode], backend: str, points: int = 9, metric: str = "success_auc",
              actions: ActionMap | None = None) -> tuple[EpisodeTuner, float]:
    """The grid action (``points`` per tuned dimension, [-1, 1]) with the best mean ``metric`` over
    ``episodes`` (``"rmse"``: lowest mean log RMSE; any other score key of :func:`bboxtune.envs.episodes.scoring.score_estimates`:
    highest mean). Returns the tuner and its mean score."""
    amap = actions or action_map(backend)
    if points < 2:
        raise ValueError(f"points={points}; allowed: >= 2")
    grid = np.array(list(itertools.product(np.linspace(-1.0, 1.0, points), repeat=amap.dim)))
    total = np.zeros(len(grid))
    for ep in episodes:
        est = run_positions(backend, ep.y, ep.tau, amap.to_params(grid, ep.nominal))
        scores = score_estimates(est, ep.truth)
        total += -np.log(scores["rmse"]) if metric == "rmse" else np.nan_to_num(scores[metric])
    best = int(np.argmax(total))
    return fixed_tuner(backend, grid[best], amap), float(total[best] / max(len(episodes), 1))


def load_tuner(path: str | os.PathLike, *, trust_pickle: bool = False) -> EpisodeTuner:
    """A fixed tuner from a JSON file (or a folder holding ``tuned.json``; :meth:`EpisodeTuner.document`), or a
    trained one from a ``scripts/train.py`` run directory (has ``config.yml``; loaded without
    unpickling, ``trust_pickle`` as in ``bboxtune.agents.training.runs.SB3Policy.load``). ValueError naming the file otherwise."""
    path = Path(path)
    if path.is_dir() and (path / "config.yml").is_file():
        run_cfg = load_config(path)
        try:
            cfg = EnvConfig.from_kwargs(**run_cfg["env_kwargs"])
        except (TypeError, ValueError) as err:
            raise ValueError(f"{path / 'config.yml'}: env_kwargs: {err}") from None
        amap = action_map(cfg.backend, cfg.tune, cfg.horizon_max, cfg.sigma_decades)
        return EpisodeTuner(SB3Policy.load(path, trust_pickle=trust_pickle), cfg.backend, amap, cfg.features == "msd")
    file = path / "tuned.json" if path.is_dir() else path
    if not file.is_file():
        raise ValueError(f"--tuned {path}: neither a train.py run directory (config.yml) nor a tuned.json file")
    try:
        doc = json.loads(textfile.read_text(file))
    except json.JSONDecodeError as err:
        raise ValueError(f"{file}:{err.lineno}:{err.colno}: invalid JSON: {err.msg}") from None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as err:
        raise ValueError(f"{file}: not a readable JSON file ({err})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{file}: expected a JSON object (a tuned.json from grid_tune)")
    if "backend" in doc and doc["backend"] not in DEFAULT_TUNE:
        raise ValueError(f"{file}: backend={doc['backend']!r}; allowed: {sorted(DEFAULT_TUNE)}")
    try:
        amap = action_map(doc["backend"], doc["tune"], doc["horizon_max"], doc["sigma_decades"])
        return fixed_tuner(doc["backend"], np.asarray(doc["action"], dtype=float), amap)
    except KeyError as err:
        raise ValueError(f"{file}: missing key {err}; a tuned.json has backend, tune, horizon_max, "
                         "sigma_decades, action") from None
    except (TypeError, ValueError) as err:
        raise ValueError(f"{file}: {err}") from None
