"""Pinned episodes of a ``FilterTune-v0`` env, kept in memory and scored in batches (for fitting baselines).

:class:`EpisodeBank` resets the env once per noise seed, keeps the observation and the
:class:`bboxtune.envs.episodes.sources.Episode`, and scores candidate actions with the env's public scoring functions
(:mod:`bboxtune.envs.episodes.scoring`), so that many episodes can be revisited without resetting the env again. Its
``score(i, actions)`` returns the same numbers as ``env.unwrapped.score(actions)`` right after
``env.reset(options={"noise_seed": seeds[i]})`` (tested).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from bboxtune.envs.data.memory import check_fits
from bboxtune.envs.episodes.actions import ActionMap, Nominal
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.scoring import reference_scores, reward_from, run_positions, score_estimates

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.track_env import TrackEnv

ScoreFn = Callable[[np.ndarray], dict[str, np.ndarray]]  # actions (A, d) -> {"reward": (A,), "rmse": (A,), ...}


def nominal_action(action_map: ActionMap, nominal: Nominal) -> np.ndarray:
    """The action (d,) that sets the nominal parameters (the fixed rule) exactly."""
    return action_map.to_actions(nominal.as_params(), nominal)[0]


def rule_action(env: gym.Env) -> np.ndarray:
    """The action (d,) that reproduces the fixed rule on the env's current episode."""
    base = cast("TrackEnv", env.unwrapped)
    return nominal_action(base.action_map, cast(Episode, base.episode).nominal)  # set by the env's reset


@dataclass(frozen=True)
class PinnedEpisode:
    """One episode and what every method needs from it."""

    noise_seed: int
    obs: np.ndarray  # (n_features,) float32, the env's observation
    episode: Episode
    rule_scores: dict[str, float]  # the fixed rule's scores (``bboxtune.envs.episodes.scoring.SCORE_KEYS``)
    reference_scores: dict[str, float]  # what the reward is measured against (the env's ``reward_baseline``)


# An EpisodeBank's bytes per episode: a fixed part and a part per frame (tracemalloc peak of 40 sim episodes: 13 / 40 /
# 148 kB at 100 / 500 / 2,000 frames; this estimate is 1.1-1.2x that)
BANK_EPISODE_BYTES = 8_000
BANK_FRAME_BYTES = 80


def check_bank_memory(n_episodes: int, frames: int, what: str) -> None:
    """``bboxtune.envs.data.memory.MemoryLimitError`` (a ``ValueError`` starting with ``what``) when an
    :class:`EpisodeBank` of ``n_episodes`` episodes of up to ``frames`` frames would not fit in the available memory."""
    check_fits(n_episodes * (BANK_EPISODE_BYTES + frames * BANK_FRAME_BYTES),
               f"{what} ({n_episodes} episodes of up to {frames} frames)")


class EpisodeBank:
    """Episodes of ``env`` pinned by ``seeds`` (and ``sequence`` for OTB sources; ``None`` lets the noise
    seed pick it, as the env does)."""

    def __init__(self, env: gym.Env, seeds: Sequence[int] | np.ndarray, *, progress: bool = False) -> None:
        base = cast("TrackEnv", env.unwrapped)
        self.backend: str = base.config.backend
        self.reward_kind: str = base.config.reward
        baseline: str = base.config.reward_baseline
        self.action_map = base.action_map
        self.items: list[PinnedEpisode] = []
        for seed in tqdm(seeds, desc="episodes", disable=not progress, leave=False):
            obs, _ = env.reset(options={"noise_seed": int(seed)})
            ep = cast(Episode, base.episode)  # set by the reset above
            rule = self._scores(ep, rule_action(env)[None])
            reference = reference_scores(baseline, rule, [ep.y], [ep.truth])
            self.items.append(PinnedEpisode(int(seed), np.asarray(obs), ep, {k: float(v[0]) for k, v in rule.items()},
                                            {k: float(v[0]) for k, v in reference.items()}))

    def head(self, n: int) -> EpisodeBank:
        """A bank of the first ``n`` episodes (the episodes are shared, not copied)."""
        sub = copy.copy(self)
        sub.items = self.items[:n]
        return sub

    def __len__(self) -> int:
        return len(self.items)

    @property
    def observations(self) -> np.ndarray:
        """(n, n_features) float32."""
        return np.stack([item.obs for item in self.items])

    def _scores(self, ep: Episode, actions: np.ndarray) -> dict[str, np.ndarray]:
        params = self.action_map.to_params(actions, ep.nominal)
        return score_estimates(run_positions(self.backend, ep.y, ep.tau, params), ep.truth)

    def score(self, i: int, actions: np.ndarray) -> dict[str, np.ndarray]:
        """Scores of actions (A, d) on episode ``i``: ``reward`` and the ``bboxtune.envs.episodes.scoring`` keys, each (A,)."""
        item = self.items[i]
        scores = self._scores(item.episode, np.atleast_2d(actions))
        return {"reward": reward_from(scores, item.reference_scores, self.reward_kind), **scores}

    def scorer(self, i: int) -> ScoreFn:
        """``score`` bound to episode ``i``."""
        return lambda actions: self.score(i, actions)

    def mean_reward(self, actions: np.ndarray) -> np.ndarray:
        """Mean reward over all episodes of each action (A, d), the same actions on every episode → (A,)."""
        return np.mean([self.score(i, actions)["reward"] for i in range(len(self))], axis=0)
