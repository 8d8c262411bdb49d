"""What FilterTune-v0 and FilterRetune-v0 share: configuration, spaces, episode drawing, the rule, and the
checks of ``reset``'s arguments.

A rejected call changes nothing: ``reset`` checks ``seed`` and ``options`` before it touches the env, and if
drawing the episode fails (an unknown or too short pinned sequence) it puts ``np_random`` back as it was, so
the current episode — and, for FilterTune-v0, its prepared block — stays as before the call; ``step``
checks the action before it advances anything.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any, cast

import gymnasium as gym
import numpy as np

from bboxtune.envs.episodes.actions import ACCEPTS, K_AXIS, ActionMap
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.features import feature_names
from bboxtune.envs.episodes.sources import make_source
from bboxtune.envs.render import draw_episode

RESET_OPTIONS = ("sequence", "noise_seed", "tracker")


def _seed_value(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}={value!r} has type {type(value).__name__}; allowed: None or an integer >= 0")
    if value < 0:
        raise ValueError(f"{name}={value!r} is out of range; allowed: None or an integer >= 0")
    return int(value)


def check_reset_args(seed: Any, options: Any) -> tuple[int | None, dict[str, Any]]:
    """``reset``'s ``seed`` and ``options`` checked (TypeError / ValueError naming the argument): ``seed`` None
    or an integer >= 0; ``options`` None or a mapping with the keys ``RESET_OPTIONS`` only — ``noise_seed``
    None or an integer >= 0, ``sequence`` and ``tracker`` None or a str. Options set to None are dropped (= not
    given)."""
    seed = None if seed is None else _seed_value("seed", seed)
    if options is None:
        return seed, {}
    if not isinstance(options, Mapping):
        raise TypeError(f"options={options!r} has type {type(options).__name__}; allowed: None or a dict with keys from "
                        f"{RESET_OPTIONS}")
    unknown = sorted(map(repr, set(options) - set(RESET_OPTIONS)))
    if unknown:
        raise ValueError(f"options: unknown reset option(s) {', '.join(unknown)}; allowed: {RESET_OPTIONS}")
    checked: dict[str, Any] = {}
    if options.get("noise_seed") is not None:
        checked["noise_seed"] = _seed_value("options['noise_seed']", options["noise_seed"])
    for key in ("sequence", "tracker"):
        value = options.get(key)
        if value is not None:
            if not isinstance(value, str):
                raise TypeError(f"options[{key!r}]={value!r} has type {type(value).__name__}; allowed: None or a {key} "
                                "name (str)")
            checked[key] = value
    return seed, checked


class TrackEnv(gym.Env):
    """Base of the bboxtune environments (not registered itself): one track per episode, drawn by the
    configured source, with the fixed rule's parameters from the episode's nominal values."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, n_extra_obs: int, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode is not None and not isinstance(render_mode, str):
            raise TypeError(f"render_mode={render_mode!r} has type {type(render_mode).__name__}; allowed: None, 'rgb_array'")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; allowed: None, 'rgb_array'")
        self.render_mode = render_mode
        self.config = EnvConfig.from_kwargs(**kwargs)
        self.source = make_source(self.config)
        # config.tune: None is resolved to the backend's default by EnvConfig.__post_init__
        self.action_map = ActionMap(tune=cast("tuple[str, ...]", self.config.tune), K=K_AXIS,
                                    horizon_max=self.config.horizon_max, sigma_decades=self.config.sigma_decades)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_map.dim,), np.float32)
        n_obs = len(feature_names(self.config.features)) + n_extra_obs
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (n_obs,), np.float32)
        self.episode: Episode | None = None

    @contextmanager
    def _seeded(self, seed: int | None) -> Iterator[None]:
        """Reseed ``np_random`` when ``seed`` is given (``gym.Env.reset``), and put it back as it was if the
        body raises (a rejected reset leaves the env as it found it)."""
        rng, rng_seed = self._np_random, self._np_random_seed
        state = None if rng is None else rng.bit_generator.state
        try:
            super().reset(seed=seed)
            yield
        except BaseException:
            self._np_random, self._np_random_seed = rng, rng_seed
            if rng is not None:
                rng.bit_generator.state = cast("Mapping[str, Any]", state)  # rng's own, saved above
            raise

    def _noise_seeds(self, count: int, rng: np.random.Generator | None = None) -> list[int]:
        """The next ``count`` episode noise seeds from ``rng`` (default ``np_random``; the same sequence whether
        drawn one at a time or in blocks)."""
        return (self.np_random if rng is None else rng).integers(2**62, size=count).tolist()

    def _draw(self, options: dict[str, Any]) -> Episode:
        """The episode checked ``options`` pin (or a fresh one from ``np_random``); a ``tracker`` option only
        where the source has trackers, and one of them (ValueError naming the option)."""
        tracker = options.get("tracker")
        if tracker is not None and tracker not in self.source.trackers:
            allowed = (f"one of this env's trackers {self.source.trackers}" if self.source.trackers else
                       f"source {self.config.source!r} here has no trackers (only 'otb_tracker' and 'mix' with "
                       "mix_weights[2] > 0 have)")
            raise ValueError(f"options['tracker']={tracker!r}; allowed: {allowed}")
        noise_seed = options.get("noise_seed")
        if noise_seed is None:
            noise_seed = self._noise_seeds(1)[0]
        pinned = {"tracker": tracker} if tracker is not None else {}
        return self.source.draw(options.get("sequence"), noise_seed, **pinned)

    @staticmethod
    def rule_params(ep: Episode) -> dict[str, np.ndarray]:
        """The fixed rule's parameters on ``ep`` as arrays (1,)."""
        return ep.nominal.as_params()

    def physical(self, params: dict[str, np.ndarray], row: int = 0) -> dict[str, float | int]:
        """The parameters the back end uses, of candidate ``row``, as Python numbers (for ``info``)."""
        return {k: (int(params[k][row]) if k == "horizon" else float(params[k][row])) for k in ACCEPTS[self.config.backend]}

    def _render(self, estimate: np.ndarray | None, frame: int | None = None) -> np.ndarray | None:
        if self.render_mode != "rgb_array" or self.episode is None:
            return None
        return draw_episode(self.episode.truth, self.episode.y, estimate, frame=frame)
