"""What FilterTune-v0 and FilterRetune-v0 share: configuration, spaces, episode drawing, the rule."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from envs.actions import ACCEPTS, ActionMap
from envs.config import EnvConfig
from envs.render import draw_episode
from envs.sources import K_AXIS, Episode, make_source

RESET_OPTIONS = ("sequence", "noise_seed")


class TrackEnv(gym.Env):
    """Base of the bboxtune environments (not registered itself): one track per episode, drawn by the
    configured source, with the fixed rule's parameters from the episode's nominal values."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, n_extra_obs: int, render_mode: str | None = None, **kwargs: Any) -> None:
        from envs.features import FEATURE_NAMES

        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; allowed: None, 'rgb_array'")
        self.render_mode = render_mode
        self.config = EnvConfig.from_kwargs(**kwargs)
        self.source = make_source(self.config)
        self.action_map = ActionMap(tune=self.config.tune, K=K_AXIS, horizon_max=self.config.horizon_max,
                                    sigma_decades=self.config.sigma_decades)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_map.dim,), np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (len(FEATURE_NAMES) + n_extra_obs,), np.float32)
        self.episode: Episode | None = None

    def _seed_and_options(self, seed: int | None, options: dict[str, Any] | None) -> dict[str, Any]:
        """Seed the env (``seed`` given: reseed ``np_random``) and return the validated reset options."""
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: {RESET_OPTIONS}")
        return options

    def _noise_seeds(self, count: int) -> list[int]:
        """The next ``count`` episode noise seeds from ``np_random`` (the same sequence whether drawn one at
        a time or in blocks)."""
        return self.np_random.integers(2**62, size=count).tolist()

    def _draw(self, seed: int | None, options: dict[str, Any] | None) -> Episode:
        """Seed the env, then draw the episode ``options`` pins (or a fresh one from ``np_random``)."""
        options = self._seed_and_options(seed, options)
        noise_seed = options.get("noise_seed")
        if noise_seed is None:
            noise_seed = self._noise_seeds(1)[0]
        return self.source.draw(options.get("sequence"), int(noise_seed))

    @staticmethod
    def rule_params(ep: Episode) -> dict[str, np.ndarray]:
        """The fixed rule's parameters on ``ep`` as arrays (1,)."""
        nominal = ep.nominal
        return {"psi": np.array([nominal.psi]), "horizon": np.array([nominal.horizon]),
                "sigma_w": np.array([nominal.sigma_w]), "sigma_v": np.array([nominal.sigma_v])}

    def physical(self, params: dict[str, np.ndarray], row: int = 0) -> dict[str, float | int]:
        """The parameters the back end uses, of candidate ``row``, as Python numbers (for ``info``)."""
        return {k: (int(params[k][row]) if k == "horizon" else float(params[k][row])) for k in ACCEPTS[self.config.backend]}

    def _render(self, estimate: np.ndarray, frame: int | None = None) -> np.ndarray | None:
        if self.render_mode != "rgb_array" or self.episode is None:
            return None
        return draw_episode(self.episode.truth, self.episode.y, estimate, frame=frame)
