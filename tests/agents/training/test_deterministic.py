"""bboxtune.agents.training.deterministic: the deterministic actions of a policy equal SB3's ``predict``, bit for bit."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import A2C, PPO, SAC, TD3

from bboxtune.agents.smoothing import pretrained
from bboxtune.agents.smoothing.tuner import load_pretrained
from bboxtune.agents.training.deterministic import deterministic_actions


class _BoxEnv(gym.Env):
    observation_space = gym.spaces.Box(-10.0, 10.0, (5,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        return np.zeros(5, np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        return np.zeros(5, np.float32), 0.0, True, False, {}


def _observations(n: int, width: int, seed: int = 0) -> np.ndarray:
    """Normalised-looking float64 observations, some beyond VecNormalize's clip (±10) and saturating tanh layers."""
    rng = np.random.default_rng(seed)
    return rng.normal(scale=3.0, size=(n, width)) * rng.choice([1.0, 5.0], size=(n, 1))


@pytest.mark.parametrize("name", pretrained.available())
def test_a_shipped_tuner_acts_as_sb3_predict(name: str) -> None:
    policy = load_pretrained(name).policy.model.policy
    obs = _observations(64, policy.observation_space.shape[0])
    expected = policy.predict(obs, deterministic=True)[0]
    assert np.array_equal(deterministic_actions(policy, obs), expected)
    for row in obs[:8, None]:  # one track at a time, as a tracker re-tunes (a batch's rows may differ in the last bit)
        assert np.array_equal(deterministic_actions(policy, row), policy.predict(row, deterministic=True)[0])


@pytest.mark.parametrize("algo", [PPO, A2C, SAC, TD3])
def test_every_algorithm_acts_as_sb3_predict(algo: type) -> None:
    """PPO / A2C through the Gaussian's mean; SAC's squashed and TD3's actor through their own ``_predict``."""
    model = algo("MlpPolicy", _BoxEnv(), seed=0, device="cpu")
    obs = _observations(32, 5, seed=1)
    actions = deterministic_actions(model.policy, obs)
    assert actions.shape == (32, 2) and np.all(np.abs(actions) <= 1.0)
    assert np.array_equal(actions, model.policy.predict(obs, deterministic=True)[0])


def test_a_policy_in_training_mode_is_switched_to_eval_mode() -> None:
    model = PPO("MlpPolicy", _BoxEnv(), seed=0, device="cpu")
    model.policy.set_training_mode(True)
    obs = _observations(4, 5)
    actions = deterministic_actions(model.policy, obs)
    assert not model.policy.training and not any(m.training for m in model.policy.modules())
    assert np.array_equal(actions, model.policy.predict(obs, deterministic=True)[0])


def test_actions_are_clipped_to_the_action_space() -> None:
    """An unsquashed Gaussian's mean can leave [-1, 1]; predict clips it, and so does this."""
    model = PPO("MlpPolicy", _BoxEnv(), seed=0, device="cpu")
    for p in model.policy.action_net.parameters():
        p.data.fill_(1.0)
    obs = np.full((3, 5), 5.0)
    actions = deterministic_actions(model.policy, obs)
    assert np.array_equal(np.abs(actions), np.ones((3, 2), dtype=np.float32))  # the mean is 64 tanh units: clipped
    assert np.array_equal(actions, model.policy.predict(obs, deterministic=True)[0])


def test_a_replaced_action_net_is_used_not_the_cached_one() -> None:
    """The layers are worked out once per policy, and again when its action networks are other modules."""
    model = PPO("MlpPolicy", _BoxEnv(), seed=0, device="cpu")
    obs = _observations(4, 5)
    before = deterministic_actions(model.policy, obs)
    model.policy.action_net = th.nn.Linear(64, 2)
    th.nn.init.constant_(model.policy.action_net.weight, 0.01)
    after = deterministic_actions(model.policy, obs)
    assert not np.array_equal(after, before)
    assert np.array_equal(after, model.policy.predict(obs, deterministic=True)[0])
