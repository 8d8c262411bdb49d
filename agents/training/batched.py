"""The stable-baselines3 face of the batched FilterTune-v0 (:mod:`bboxtune.envs.vector`): :class:`TuneVecEnv`."""

from __future__ import annotations

import time
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from bboxtune.envs.vector import TuneBatch


class TuneVecEnv(VecEnv):
    """stable-baselines3 ``VecEnv`` over a :class:`bboxtune.envs.vector.TuneBatch`: all n envs step, finish and auto-reset
    together (every info holds ``terminal_observation``, ``TimeLimit.truncated = False`` and, as SB3's ``Monitor``
    writes it, ``episode`` = return, length 1 and seconds since start — so no Monitor wrapper is needed and
    VecNormalize's eval sync sees the same wrapper depth as for a DummyVecEnv). ``seed(s)`` (SB3's model seeding)
    restarts the noise-seed generator at the next ``reset``; reset options are refused (pin episodes with a single
    env); ``get_attr`` / ``env_method`` reach the batch's one configured env (the same for every index)."""

    def __init__(self, batch: TuneBatch, seed: int | None = None) -> None:
        self.batch = batch
        env = batch.env
        super().__init__(batch.n_envs, env.observation_space, env.action_space)
        batch.seed(seed)
        self._actions: np.ndarray | None = None
        self._obs: np.ndarray | None = None
        self._t_start = time.time()

    def reset(self) -> np.ndarray:
        if any(self._options):
            raise ValueError("reset options: not supported by the batched env (pin episodes with a single env)")
        if self._seeds[0] is not None:
            self.batch.seed(self._seeds[0])
        self._reset_seeds()
        self._reset_options()
        self._obs, self.reset_infos = self.batch.reset()
        return self._obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None or self._obs is None:
            raise RuntimeError("step_wait() without reset() and step_async()")
        actions, self._actions = self._actions, None
        rewards, infos = self.batch.step(actions)
        elapsed = round(time.time() - self._t_start, 6)
        for info, last, reward in zip(infos, self._obs, rewards.tolist(), strict=False):
            info["terminal_observation"] = last  # every episode ends after its one step
            info["TimeLimit.truncated"] = False
            info["episode"] = {"r": float(reward), "l": 1, "t": elapsed}
        self._obs, self.reset_infos = self.batch.reset()
        return self._obs.copy(), rewards.astype(np.float32), np.ones(self.num_envs, dtype=bool), infos

    def close(self) -> None:
        self.batch.env.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.batch.env, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        raise AttributeError(f"set_attr({attr_name!r}): the batched envs share one configuration; make a new batch")

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        method = getattr(self.batch.env, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
