"""``bboxtune/FilterTune-v0`` batched: n episodes reset, stepped and scored together in one process.

FilterTune-v0 is a contextual bandit (one step per track), so n envs step in lockstep and all auto-reset after
every step. :class:`TuneBatch` does that work once for all n tracks — one vectorised simulation
(``Source.draw_many``), one run of the fixed rule and one feature pass (``FilterTuneEnv.prepare``), one
batched filter run of the n actions (``bboxtune.envs.episodes.scoring.run_tracks``: one call per track length; the FIR family
and the Kalman filters run in frame units, so tracks of different τ share it) and one scoring pass — where n
separate envs would each pay for their own Python loop over time. Each of these splits its tracks over the kernel
threads (``bboxtune.filters.threads.in_threads``; the same numbers for any thread count), and making a batch sets
glibc's malloc to keep the memory a step frees for the next (``bboxtune.filters.allocator``). Two faces over it:

* :class:`TuneVectorEnv`, a Gymnasium ``VectorEnv`` with same-step auto-reset, registered as the env's
  ``vector_entry_point``: ``bboxtune.envs.make_vec(env_id, n, **kwargs)`` = ``gym.make_vec(env_id, num_envs=n,
  **kwargs)``; the finished episode's observation and step info are in ``infos["final_obs"]`` /
  ``infos["final_info"]``;
* ``bboxtune.agents.training.batched.TuneVecEnv``, the stable-baselines3 ``VecEnv`` that ``scripts/train.py --vec batched``
  trains on (``bboxtune.agents.training.runs.make_vec``; kept in ``agents`` so that ``import envs`` needs no torch).

Every step's info (per env) is what ``FilterTuneEnv.step`` returns for that track. Episodes are drawn as by
the single env — each a pure function of its noise seed — but the noise seeds come from the batch's own
generator (seeded by ``reset(seed=...)``), n at a time, through ``noise_seeds(rng, n)``: by default uniform on
[0, 2⁶²) like the env's own draws (``bboxtune.agents.splits.train_seeds`` for the train split in training). Pinned
episodes (reset options) are the single env's job; ``render_mode`` is not supported.

Memory: a batch holds n episodes at once, so ``n_envs`` is bounded by the machine's available memory, not by a
fixed cap — :class:`TuneBatch` refuses (``bboxtune.envs.data.memory.MemoryLimitError``, a ``ValueError`` with the
estimate) when :func:`batch_bytes` of ``n_envs`` episodes of the source's longest length exceeds it.

>>> from bboxtune import envs
>>> venv = envs.make_vec("bboxtune/FilterTune-v0", 4, backend="ufir_cmn", track_length=200)
>>> obs, infos = venv.reset(seed=0)
>>> obs.shape, sorted(infos["track"])
((4, 20), ['_noise_seed', '_sequence', '_tau', 'noise_seed', 'sequence', 'tau'])
>>> obs, rewards, terminated, truncated, infos = venv.step(np.zeros((4, 2), np.float32))
>>> rewards.shape, bool(terminated.all()), bool(truncated.any()), infos["final_info"]["rmse"].shape
((4,), True, False, (4,))
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from bboxtune.envs.data.memory import check_fits
from bboxtune.envs.episodes.scoring import SCORE_KEYS, reward_from, run_tracks, score_tracks
from bboxtune.envs.tune_env import FilterTuneEnv
from bboxtune.filters.allocator import keep_freed_memory

TUNE_ID = "bboxtune/FilterTune-v0"
BATCHED_IDS = (TUNE_ID,)  # env ids with a batched vector env
NoiseSeeds = Callable[[np.random.Generator, int], np.ndarray]
# Memory of one episode of a batch, peak over a cycle (construction, reset, step, reset): its arrays (measurements,
# truth, the rule's and the action's estimates, features, scores) per frame and the Python objects around it
# (tracemalloc, sim episodes of kf_cmn, the most of the back ends: 10 kB per 10-frame episode, 390 B per frame at
# 1000 frames, 350 B at 5000; the estimate is 1.2-1.3 times these, tests/envs/test_memory.py)
EPISODE_FRAME_BYTES = 450
EPISODE_BYTES = 8192


def batch_bytes(n_episodes: int, n_frames: int) -> int:
    """Estimated memory (bytes) of ``n_episodes`` episodes of at most ``n_frames`` frames prepared and scored at once."""
    return n_episodes * (EPISODE_BYTES + EPISODE_FRAME_BYTES * n_frames)


def any_noise_seeds(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` noise seeds uniform on [0, 2⁶²) (the single env's own draw)."""
    return rng.integers(2**62, size=n)


class TuneBatch:
    """n FilterTune-v0 episodes at once: :meth:`reset` draws and prepares n new tracks, :meth:`step` scores one
    action per track. ``env_kwargs`` are ``gym.make``'s (``bboxtune.envs.episodes.config.EnvConfig`` fields), checked the same
    way; ``self.env`` is the single env whose configuration, source and rule the batch uses. ``n_envs`` whose
    :func:`batch_bytes` exceed the available memory raise ``MemoryLimitError`` (module docstring)."""

    def __init__(self, n_envs: int, noise_seeds: NoiseSeeds = any_noise_seeds, **env_kwargs: Any) -> None:
        if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs={n_envs!r}; allowed: an integer >= 1")
        if "render_mode" in env_kwargs:
            raise TypeError("render_mode: not supported by the batched env (render a single env)")
        self.env = FilterTuneEnv(**env_kwargs)
        self.n_envs = int(n_envs)
        keep_freed_memory()  # a step allocates and frees tens of MB (module docstring)
        frames = self.env.source.max_frames()
        check_fits(batch_bytes(self.n_envs, frames), f"n_envs={self.n_envs} (episodes of up to {frames} frames at once)")
        self.noise_seeds = noise_seeds
        self.rng = np.random.default_rng()
        self.prepared: list[tuple[Any, dict[str, Any], np.ndarray]] = []

    def seed(self, seed: int | None) -> None:
        """Restart the noise-seed generator (``None``: fresh entropy)."""
        self.rng = np.random.default_rng(seed)

    def reset(self) -> tuple[np.ndarray, list[dict[str, Any]]]:
        """n new episodes: observations (n, obs_dim) float32 and each reset ``info`` (``{"track": ...}``)."""
        seeds = [int(s) for s in self.noise_seeds(self.rng, self.n_envs)]
        self.prepared = self.env.prepare(self.env.source.draw_many(seeds))
        obs = np.stack([p[2] for p in self.prepared]).astype(np.float32, copy=False)
        return obs, [{"track": dict(p[0].meta)} for p in self.prepared]

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, list[dict[str, Any]]]:
        """Score ``actions`` (n, d), one per current episode (checked as ``FilterTuneEnv.score`` checks a batch):
        rewards (n,) float64 and each step ``info``, as the single env's."""
        if not self.prepared:
            raise RuntimeError("call reset() before step()")
        env = self.env
        a = env.action_map.check(actions)
        if a.shape[0] != self.n_envs or np.ndim(actions) != 2:
            raise ValueError(f"actions have shape {np.shape(actions)}; allowed ({self.n_envs}, {env.action_map.dim}): "
                             "one action per env")
        episodes = [p[0] for p in self.prepared]
        params = env.action_map.to_params(a, [ep.nominal for ep in episodes])
        estimates = run_tracks(env.config.backend, [ep.y for ep in episodes], [ep.tau for ep in episodes], params)
        scores = score_tracks(estimates, [ep.truth for ep in episodes])
        reference = {k: np.array([p[1]["reference"][k] for p in self.prepared]) for k in SCORE_KEYS}
        rewards = reward_from(scores, reference, env.config.reward)
        # step_info reads one row of each: Python lists (the same numbers) index faster than arrays
        result = {**{k: v.tolist() for k, v in scores.items()}, "params": {k: v.tolist() for k, v in params.items()}}
        infos = [env.step_info(result, i, (p[0], p[1])) for i, p in enumerate(self.prepared)]
        self.prepared = []
        return rewards, infos


class TuneVectorEnv(VectorEnv):
    """Gymnasium ``VectorEnv`` over a :class:`TuneBatch` with same-step auto-reset (module docstring);
    ``reset(seed=s)`` restarts the noise-seed generator (a list: its first entry), ``options`` are refused."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, num_envs: int, noise_seeds: NoiseSeeds = any_noise_seeds, **env_kwargs: Any) -> None:
        self.batch = TuneBatch(num_envs, noise_seeds, **env_kwargs)
        env = self.batch.env
        self.num_envs = self.batch.n_envs
        self.single_observation_space, self.single_action_space = env.observation_space, env.action_space
        self.observation_space = batch_space(env.observation_space, self.num_envs)
        self.action_space = batch_space(env.action_space, self.num_envs)
        self._obs: np.ndarray | None = None

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        if options:
            raise ValueError("reset options: not supported by the batched env (pin episodes with a single env)")
        if seed is not None:
            self.batch.seed(seed if isinstance(seed, (int, np.integer)) else seed[0])
        self._obs, infos = self.batch.reset()
        return self._obs.copy(), self._merge(infos)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        rewards, infos = self.batch.step(actions)
        finished = [{"final_obs": last, "final_info": info} for last, info in zip(self._obs, infos, strict=False)]
        self._obs, reset_infos = self.batch.reset()
        merged = self._merge([{**f, **r} for f, r in zip(finished, reset_infos, strict=False)])
        n = self.num_envs
        return self._obs.copy(), rewards, np.ones(n, dtype=bool), np.zeros(n, dtype=bool), merged

    def _merge(self, infos: list[dict[str, Any]]) -> dict[str, Any]:
        merged: dict[str, Any] = {}
        for i, info in enumerate(infos):
            merged = self._add_info(merged, info, i)
        return merged

    def close_extras(self, **kwargs: Any) -> None:
        self.batch.env.close()


def make_vec(env_id: str, n_envs: int, **env_kwargs: Any) -> VectorEnv:
    """A Gymnasium ``VectorEnv`` of ``n_envs`` envs of ``env_id`` with ``gym.make``'s keyword arguments:
    :class:`TuneVectorEnv` (batched, same-step auto-reset) for ``bboxtune/FilterTune-v0``; Gymnasium's
    ``SyncVectorEnv`` for the other ids (FilterRetune-v0's episodes last several steps: nothing to batch)."""
    return gym.make_vec(env_id, num_envs=n_envs, **env_kwargs)
