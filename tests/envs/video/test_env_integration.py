"""``source="video"`` in the gym envs: the env checkers pass and pinned episodes replay exactly."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from bboxtune import envs  # noqa: F401  (registers the ids)

SETTINGS = {"source": "video", "detector": "regions", "video_pool": 2, "video_size": (128, 96)}


@pytest.fixture
def video_env():
    def make(env_id: str, **kwargs):
        return gym.make(env_id, **SETTINGS, **kwargs)

    return make


@pytest.mark.parametrize("env_id", ["bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"])
def test_env_checker_passes_with_video_episodes(video_env, env_id):
    env = video_env(env_id, backend="kf", track_length=100, window=20, history=20)
    check_env(env.unwrapped, skip_render_check=True)


def test_pinned_video_episode_replays(video_env):
    env = video_env("bboxtune/FilterTune-v0", backend="ufir_cmn", track_length=60)
    obs1, _ = env.reset(options={"sequence": "train-00001", "noise_seed": 3})
    _, r1, *_ = env.step(np.zeros(2, np.float32))
    obs2, _ = env.reset(seed=9, options={"sequence": "train-00001", "noise_seed": 3})
    _, r2, *_ = env.step(np.zeros(2, np.float32))
    np.testing.assert_array_equal(obs1, obs2)
    assert r1 == r2 and env.unwrapped.episode.meta["detector"] == "regions"


def test_unknown_detector_fails_loudly():
    with pytest.raises(ValueError, match="detector"):
        gym.make("bboxtune/FilterTune-v0", source="video", detector="surf")
