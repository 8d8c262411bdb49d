"""Hyperparameters per algorithm and env id, from YAML files in the RL Baselines3 Zoo layout.

``agents/hyperparams/<algo>.yml`` maps env ids to complete settings. As in the zoo, an env id's own entry is used
as is and the ``default:`` entry serves any env id without one; files share settings through a YAML anchor and
``<<:`` merge keys, which ``yaml.safe_load`` resolves. The zoo loads the shipped files unchanged
(``python -m rl_zoo3.train --algo ppo --env bboxtune/FilterTune-v0 --gym-packages bboxtune -conf
agents/hyperparams/ppo.yml``, tested per file). The one setting only this loader reads, ``vec_env``, is a top-level
key: the zoo looks up env ids only (its option is ``--vec-env``), while inside an entry it would pass the key to the
algorithm's constructor. A file entry the zoo would reject is refused here too: it must hold ``n_timesteps`` and
``policy``, no ``vec_env`` and no ``activation_fn`` name (the zoo needs a class there; name one in ``overrides``).
Nothing is ``eval``'d: the string forms of ``policy_kwargs`` and ``normalize`` that the zoo ``eval``s are refused.

| key                  | YAML form                                        | becomes                                      |
|----------------------|--------------------------------------------------|----------------------------------------------|
| ``n_timesteps``      | int                                              | default ``--timesteps`` of ``train.py``      |
| ``n_envs``           | int                                              | default ``--n-envs``                         |
| ``vec_env``          | ``batched``, ``subproc`` or ``dummy`` (top level | ``bboxtune.agents.training.batched.TuneVecEnv`` |
|                      | or override); a file's ``batched`` means         | (one process, all envs in one batch;         |
|                      | ``subproc`` for env ids without a batched form   | FilterTune-v0 only) / SubprocVecEnv /        |
|                      |                                                  | DummyVecEnv                                  |
| ``normalize``        | bool or mapping of VecNormalize kwargs           | ``VecNormalize(**kwargs)`` (true: obs only)  |
| ``policy``           | str (``MlpPolicy``)                              | policy                                       |
| ``learning_rate``, ``clip_range`` | float or ``lin_<float>``            | constant, or linear decay to 0 (``LinearSchedule``) |
| ``policy_kwargs``    | mapping; ``activation_fn: tanh|relu|elu|leaky_relu`` | the mapping, activation as a ``torch.nn`` class |
|                      | (``activation_fn``: in overrides only)           |                                              |
| ``train_freq``       | int or ``[n, step|episode]``                     | int / tuple                                  |
| ``noise_type``, ``noise_std`` | ``normal`` and a float (TD3/SAC)        | ``NormalActionNoise`` on every action entry  |
| anything else        | scalar                                           | keyword argument of the algorithm's constructor |
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch.nn as nn
from stable_baselines3.common.noise import NormalActionNoise
from stable_baselines3.common.utils import LinearSchedule

from bboxtune.agents import readers
from bboxtune.agents.training.algos import algo_class
from bboxtune.envs.vector import BATCHED_IDS

HYPERPARAMS_DIR = Path(__file__).resolve().parents[1] / "hyperparams"  # agents/hyperparams/
ACTIVATIONS: dict[str, type[nn.Module]] = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU, "leaky_relu": nn.LeakyReLU}
VEC_ENVS = ("batched", "subproc", "dummy")
FILE_KEYS = ("vec_env",)  # top-level settings of a file, read by this loader only
ZOO_REQUIRED = ("n_timesteps", "policy")  # the zoo's KeyError / TypeError without them
_SCHEDULED = ("learning_rate", "clip_range")


@dataclass(frozen=True)
class Hyperparams:
    """Settings of one training run: what ``train.py`` uses plus the algorithm's constructor kwargs."""

    algo: str
    env_id: str
    n_timesteps: int  # default total environment steps
    n_envs: int  # parallel envs
    vec_env: str  # "batched" | "subproc" | "dummy"
    normalize: dict[str, Any]  # VecNormalize kwargs; empty: no VecNormalize
    policy: str
    raw: dict[str, Any]  # the merged YAML entry as read (for config.yml)
    algo_kwargs: dict[str, Any] = field(default_factory=dict)  # parsed: ready for the constructor (without env)


def parse_schedule(value: Any, *, where: str) -> float | LinearSchedule:
    """``3e-4`` → 3e-4; ``"lin_3e-4"`` → linear decay from 3e-4 (start of training) to 0 (end)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            raise ValueError(f"{where}: {value!r} is not 'lin_<float>'") from None
        return LinearSchedule(start=start, end=0.0, end_fraction=1.0)
    raise ValueError(f"{where}: {value!r}; allowed: a number or 'lin_<float>'")


def _policy_kwargs(value: Any, *, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ValueError(f"{where}: policy_kwargs must be a mapping, got {value!r}")
    out = dict(value)
    if "activation_fn" in out:
        name = out["activation_fn"]
        if name not in ACTIVATIONS:
            raise ValueError(f"{where}: activation_fn={name!r}; allowed: {sorted(ACTIVATIONS)}")
        out["activation_fn"] = ACTIVATIONS[name]
    return out


def _train_freq(value: Any, *, where: str) -> int | tuple[int, str]:
    if isinstance(value, int):
        return value
    if isinstance(value, list) and len(value) == 2 and isinstance(value[0], int) and value[1] in ("step", "episode"):
        return (value[0], value[1])
    raise ValueError(f"{where}: train_freq={value!r}; allowed: int or [n, 'step' | 'episode']")


def read_entry(path: Path, env_id: str) -> dict[str, Any]:
    """The entry of ``env_id`` in ``path`` (else its ``default:`` entry), with the file's top-level ``vec_env``."""
    data = readers.read_yaml(path) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping of env ids (and 'default') to mappings of settings")
    bad = sorted(str(k) for k, v in data.items() if not isinstance(v, dict) and k not in FILE_KEYS)
    if bad:
        raise ValueError(f"{path}: top-level {bad} must map to settings; top-level settings allowed: {FILE_KEYS}")
    if env_id not in data and "default" not in data:
        raise ValueError(f"{path}: neither a 'default' entry nor one for {env_id!r}; entries: {sorted(map(str, data))}")
    key = env_id if env_id in data else "default"
    entry = dict(data[key])
    where = f"{path} [{key}]"
    missing = [k for k in ZOO_REQUIRED if k not in entry]
    if missing:
        raise ValueError(f"{where}: {missing} missing; every entry needs {ZOO_REQUIRED} (the zoo reads an entry as is)")
    if "vec_env" in entry:
        raise ValueError(f"{where}: vec_env inside an entry (the zoo would pass it to the algorithm); "
                         "set it as a top-level key of the file")
    if isinstance(entry.get("policy_kwargs"), dict) and "activation_fn" in entry["policy_kwargs"]:
        raise ValueError(f"{where}: policy_kwargs.activation_fn in a file (the zoo needs a class there); "
                         "pass it as an override, e.g. train.py --hyperparams 'policy_kwargs:{activation_fn: relu}'")
    return {**entry, **{k: data[k] for k in FILE_KEYS if k in data}}


def load_hyperparams(algo: str, env_id: str, overrides: dict[str, Any] | None = None,
                     directory: Path = HYPERPARAMS_DIR) -> Hyperparams:
    """Read ``<directory>/<algo>.yml`` for ``env_id``, apply ``overrides`` (same YAML forms) and parse."""
    cls = algo_class(algo)
    path = Path(directory) / f"{algo}.yml"
    raw = {**read_entry(path, env_id), **(overrides or {})}
    entry = dict(raw)
    where = f"{path} [{env_id}]"
    n_timesteps = int(entry.pop("n_timesteps"))
    n_envs = int(entry.pop("n_envs", 1))
    vec_env = entry.pop("vec_env", "dummy")
    if vec_env not in VEC_ENVS:
        raise ValueError(f"{where}: vec_env={vec_env!r}; allowed: {VEC_ENVS}")
    if vec_env == "batched" and env_id not in BATCHED_IDS:
        if "vec_env" in (overrides or {}):
            raise ValueError(f"{where}: vec_env='batched' exists for {BATCHED_IDS} only; allowed here: 'subproc', 'dummy'")
        vec_env = raw["vec_env"] = "subproc"  # the file's default where the env has no batched form (config.yml keeps it)
    normalize = entry.pop("normalize", False)
    if normalize is True:
        normalize = {"norm_obs": True, "norm_reward": False}
    elif normalize is False:
        normalize = {}
    elif not isinstance(normalize, dict):
        raise ValueError(f"{where}: normalize={normalize!r}; allowed: true, false or a mapping of VecNormalize kwargs")
    policy = entry.pop("policy")
    if n_timesteps < 1 or n_envs < 1:
        raise ValueError(f"{where}: n_timesteps={n_timesteps}, n_envs={n_envs}; allowed: integers >= 1")
    noise_type, noise_std = entry.pop("noise_type", None), entry.pop("noise_std", None)
    kwargs: dict[str, Any] = {}
    for key, value in entry.items():
        if key in _SCHEDULED:
            kwargs[key] = parse_schedule(value, where=f"{where} {key}")
        elif key == "policy_kwargs":
            kwargs[key] = _policy_kwargs(value, where=where)
        elif key == "train_freq":
            kwargs[key] = _train_freq(value, where=where)
        else:
            kwargs[key] = value
    if noise_type is not None:
        if noise_type != "normal" or not isinstance(noise_std, (int, float)):
            raise ValueError(f"{where}: noise_type={noise_type!r}, noise_std={noise_std!r}; allowed: 'normal' and a float")
        kwargs["action_noise"] = float(noise_std)  # turned into NormalActionNoise once the action size is known
    accepted = set(inspect.signature(cls.__init__).parameters) - {"self", "policy", "env"}
    unknown = sorted(set(kwargs) - accepted)
    if unknown:
        raise ValueError(f"{where}: {unknown} not accepted by {cls.__name__}; allowed: {sorted(accepted)}")
    return Hyperparams(algo=algo, env_id=env_id, n_timesteps=n_timesteps, n_envs=n_envs, vec_env=vec_env,
                       normalize=normalize, policy=policy, raw=raw, algo_kwargs=kwargs)


def constructor_kwargs(hp: Hyperparams, action_dim: int) -> dict[str, Any]:
    """``hp.algo_kwargs`` with the action noise (if any) built for ``action_dim`` action entries."""
    kwargs = dict(hp.algo_kwargs)
    if "action_noise" in kwargs:
        std = kwargs["action_noise"]
        kwargs["action_noise"] = NormalActionNoise(mean=np.zeros(action_dim), sigma=std * np.ones(action_dim))
    return kwargs
