"""The memory a training run will need, estimated before any of it is allocated, so that ``train.py`` refuses a run
that cannot fit (one line, exit 2, nothing written) instead of dying of ``MemoryError`` part way.

The estimate adds what grows with the settings:

* the training envs' episodes (``bboxtune.envs.vector.batch_bytes`` of the source's longest episode): ``n_envs``
  at once in the batched env; in other vec envs each FilterTune-v0 env prepares a block of episodes
  (``source.block``), and each SubprocVecEnv worker is a Python process with numpy and torch imported
  (:data:`SUBPROCESS_BYTES`);
* SB3's buffer, float32: on-policy a rollout buffer of ``n_steps`` × ``n_envs`` rows (observation, action and six
  scalars: reward, return, episode start, value, log-probability, advantage), held twice while training flattens
  it, plus ppo_lstm's four LSTM states per row; off-policy a replay buffer of ``buffer_size`` rows (observation,
  next observation, action, reward, done, timeout).
"""

from __future__ import annotations

import inspect
from typing import Any, cast

import gymnasium as gym
import numpy as np

from bboxtune.agents.training.algos import RECURRENT, algo_class
from bboxtune.agents.training.hyperparams import Hyperparams
from bboxtune.envs.data.memory import check_fits
from bboxtune.envs.track_env import TrackEnv
from bboxtune.envs.tune_env import FilterTuneEnv
from bboxtune.envs.vector import batch_bytes

FLOAT32 = 4
ROLLOUT_SCALARS = 6  # reward, return, episode start, value, log-probability, advantage
REPLAY_SCALARS = 3  # reward, done, timeout
SUBPROCESS_BYTES = 256 * 2**20  # private memory of one worker process (measured: ~250 MB with torch imported)


def setting(hp: Hyperparams, name: str) -> Any:
    """The constructor argument ``name`` of the run's algorithm: from the hyperparameters, else SB3's default."""
    if name in hp.algo_kwargs:
        return hp.algo_kwargs[name]
    return inspect.signature(algo_class(hp.algo)).parameters[name].default


def off_policy(hp: Hyperparams) -> bool:
    """Whether the run's algorithm keeps a replay buffer (SAC, TD3) rather than a rollout buffer."""
    return "buffer_size" in inspect.signature(algo_class(hp.algo)).parameters


def buffer_bytes(hp: Hyperparams, obs_dim: int, action_dim: int) -> int:
    """SB3's rollout or replay buffer for these hyperparameters (module docstring), in bytes."""
    if off_policy(hp):
        return int(setting(hp, "buffer_size")) * (2 * obs_dim + action_dim + REPLAY_SCALARS) * FLOAT32
    row = obs_dim + action_dim + ROLLOUT_SCALARS
    if hp.algo in RECURRENT:
        policy_kwargs = hp.algo_kwargs.get("policy_kwargs", {})
        row += 4 * int(policy_kwargs.get("n_lstm_layers", 1)) * int(policy_kwargs.get("lstm_hidden_size", 256))
    return 2 * int(setting(hp, "n_steps")) * hp.n_envs * row * FLOAT32


def env_bytes(hp: Hyperparams, env: gym.Env) -> int:
    """The training envs' memory (module docstring) for ``hp.n_envs`` envs like ``env``, in bytes."""
    base = cast(TrackEnv, env.unwrapped)
    per_env = 1 if hp.vec_env == "batched" or not isinstance(base, FilterTuneEnv) else base.source.block
    workers = hp.n_envs * SUBPROCESS_BYTES if hp.vec_env == "subproc" else 0
    return batch_bytes(hp.n_envs * per_env, base.source.max_frames()) + workers


def check_training_memory(hp: Hyperparams, env: gym.Env) -> None:
    """``bboxtune.envs.data.memory.MemoryLimitError`` (a ``ValueError``) when a run with ``hp`` on envs like ``env`` (one of
    the training split) would need more memory than this machine has available."""
    obs_dim = int(np.prod(cast(tuple[int, ...], env.observation_space.shape)))
    action_dim = int(np.prod(cast(tuple[int, ...], env.action_space.shape)))
    steps = f"buffer_size={setting(hp, 'buffer_size')}" if off_policy(hp) else f"n_steps={setting(hp, 'n_steps')}"
    check_fits(env_bytes(hp, env) + buffer_bytes(hp, obs_dim, action_dim),
               f"n_envs={hp.n_envs} with {steps} ({hp.algo}, vec_env {hp.vec_env})")
