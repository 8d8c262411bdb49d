"""agents.runs.hold_constant_features: a feature that never varied in training is held at its training value
instead of being divided by √ε and saturated by VecNormalize (the sim → OTB collapse on other track lengths)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from agents.runs import CONSTANT_FEATURE_VAR, SB3Policy, hold_constant_features

MEAN = np.array([0.0, np.log(500.0), 1.0])  # feature 1: log_n_frames of 500-frame training tracks
VAR = np.array([1.0, 4e-8, 3e-3])  # 4e-8: what float32 rounding of a constant leaves; 3e-3: a real small variance


class _BoxEnv(gym.Env):
    observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        return np.zeros(3, np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        return np.zeros(3, np.float32), 0.0, True, False, {}


def _normalizer(var: np.ndarray = VAR) -> VecNormalize:
    norm = VecNormalize(DummyVecEnv([_BoxEnv]), training=False, norm_reward=False)
    norm.obs_rms.mean, norm.obs_rms.var = MEAN.copy(), var.copy()
    return norm


class _RecordingModel:
    """Stands in for an SB3 model: returns the first normalised feature as the action, keeps what it was given."""

    def predict(self, obs: np.ndarray, **_: Any) -> tuple[np.ndarray, None]:
        self.seen = np.array(obs)
        return obs[:, :1], None


def test_a_constant_feature_is_held_and_the_others_pass_through() -> None:
    obs = np.array([[0.5, np.log(347.0), 1.2], [-2.0, np.log(3872.0), 0.9]], dtype=np.float32)
    held = hold_constant_features(obs, _normalizer())
    assert np.allclose(held[:, 1], np.log(500.0))
    assert np.array_equal(held[:, [0, 2]], obs[:, [0, 2]])
    assert obs[0, 1] == np.float32(np.log(347.0))  # the input is not modified


def test_without_holding_vecnormalize_saturates_a_constant_feature() -> None:
    """The failure the holding removes: a 347-frame track's log_n_frames is over 1,000 standard deviations away."""
    norm = _normalizer()
    obs = np.array([[0.5, np.log(347.0), 1.2]], dtype=np.float32)
    assert norm.normalize_obs(obs)[0, 1] == pytest.approx(-norm.clip_obs)
    assert norm.normalize_obs(hold_constant_features(obs, norm))[0, 1] == pytest.approx(0.0, abs=1e-3)


@pytest.mark.parametrize("var", [np.array([1.0, 2e-6, 3e-3]), np.array([1.0, CONSTANT_FEATURE_VAR, 1.0])])
def test_features_that_varied_are_untouched(var: np.ndarray) -> None:
    obs = np.array([[0.5, 9.0, 1.2]], dtype=np.float32)
    assert np.array_equal(hold_constant_features(obs, _normalizer(var)), obs)


def test_sb3_policy_feeds_the_held_features_to_the_model() -> None:
    model = _RecordingModel()
    policy = SB3Policy(model, _normalizer(), "ppo")  # type: ignore[arg-type]
    policy.predict(np.array([[0.5, np.log(100.0), 1.2]], dtype=np.float32))
    assert model.seen[0, 1] == pytest.approx(0.0, abs=1e-3)
    assert model.seen[0, 0] == pytest.approx(0.5, abs=1e-3)
