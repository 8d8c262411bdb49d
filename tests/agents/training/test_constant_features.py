"""bboxtune.agents.training.runs.hold_constant_features: a feature that never varied in training is held at its training value
instead of being divided by √ε and saturated by VecNormalize (the sim → OTB collapse on other track lengths)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from bboxtune.agents.training import runs
from bboxtune.agents.training.runs import SB3Policy, constant_features, describe_held_features, hold_constant_features

MEAN = np.array([0.0, np.log(500.0), 1.0])  # feature 1: log_n_frames of 500-frame training tracks
# 4e-8: what the running prior leaves in a constant after 1e5 steps; 3e-3: a real small variance
VAR = np.array([1.0, 4e-8, 3e-3])


class _BoxEnv(gym.Env):
    observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        return np.zeros(3, np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        return np.zeros(3, np.float32), 0.0, True, False, {}


def _normalizer(var: np.ndarray = VAR, count: float = 1e5) -> VecNormalize:
    norm = VecNormalize(DummyVecEnv([_BoxEnv]), training=False, norm_reward=False)
    norm.obs_rms.mean, norm.obs_rms.var, norm.obs_rms.count = MEAN.copy(), var.copy(), count
    return norm


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


def test_features_that_varied_are_untouched() -> None:
    obs = np.array([[0.5, 9.0, 1.2]], dtype=np.float32)
    assert np.array_equal(hold_constant_features(obs, _normalizer(np.array([1.0, 2e-6, 3e-3]))), obs)


@pytest.mark.parametrize("steps", [64, 5000])
def test_a_short_training_run_is_judged_net_of_the_running_statistics_prior(steps: int) -> None:
    """SB3's running statistics start at mean 0, var 1: after 64 steps a constant feature still shows var ~3e-5."""
    norm = _normalizer()
    norm.obs_rms = type(norm.obs_rms)(shape=(3,))
    rng = np.random.default_rng(0)
    for _ in range(steps // 4):
        batch = np.column_stack([rng.normal(size=4), np.full(4, np.log(100.0)), 1.0 + 0.05 * rng.normal(size=4)])
        norm.obs_rms.update(batch)
    if steps == 64:
        assert norm.obs_rms.var[1] > 1e-6  # the prior, not the data: above the absolute threshold alone
    assert constant_features(norm).tolist() == [False, True, False]


def test_sb3_policy_feeds_the_held_features_to_the_model(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[np.ndarray] = []

    def recording(policy: Any, obs: np.ndarray) -> np.ndarray:  # the first normalised feature as the action
        seen.append(np.array(obs))
        return obs[:, :1]

    monkeypatch.setattr(runs, "deterministic_actions", recording)
    policy = SB3Policy(SimpleNamespace(policy=None), _normalizer(), "ppo")  # type: ignore[arg-type]
    policy.predict(np.array([[0.5, np.log(100.0), 1.2]], dtype=np.float32))
    assert seen[0][0, 1] == pytest.approx(0.0, abs=1e-3)
    assert seen[0][0, 0] == pytest.approx(0.5, abs=1e-3)


def test_summaries_name_the_held_inputs_per_tuner() -> None:
    """Feature 1 is log_tau (bboxtune.envs.episodes.features.FEATURE_NAMES); a tuner without statistics holds nothing."""
    norm = _normalizer()
    assert describe_held_features({"ppo": norm, "ppo_best": norm, "sac": None}) == "ppo, ppo_best: log_tau; sac: none"
    assert describe_held_features({"ppo": _normalizer(np.ones(3)), "sac": None}) == "none"


def test_held_inputs_of_a_re_tuning_observation_are_named_by_its_env() -> None:
    """Entries past FEATURE_NAMES get the FilterRetune-v0 observation's names (obs[i] only past any name given)."""
    from bboxtune.agents.training.runs import observation_names
    from bboxtune.envs.episodes.features import FEATURE_NAMES

    kwargs = {"window": 10, "retune_view": "offline"}
    names = observation_names("bboxtune/FilterRetune-v0", kwargs)
    assert names == gym.make("bboxtune/FilterRetune-v0", **kwargs).unwrapped.observation_names
    assert observation_names("bboxtune/FilterTune-v0", {}) == FEATURE_NAMES
    var = np.ones(len(names))
    var[[names.index("progress"), names.index("track_log_tau")]] = 0.0
    norm = _normalizer(var)
    norm.obs_rms.mean = np.zeros(len(names))
    assert describe_held_features({"ppo": norm}, {"ppo": names}) == "ppo: progress, track_log_tau"
    assert describe_held_features({"ppo": norm}) == f"ppo: obs[{names.index('progress')}], obs[{names.index('track_log_tau')}]"


@pytest.mark.parametrize("var", [VAR, np.ones(3)])
def test_the_policy_normalises_as_vecnormalize_bit_for_bit_and_follows_new_statistics(var: np.ndarray) -> None:
    """SB3Policy's cached normalisation (bboxtune.agents.training.obs_normalization) equals
    ``normalize_obs(hold_constant_features(obs))``, clipping included, and is rebuilt when the statistics change."""
    norm = _normalizer(var)
    policy = SB3Policy(SimpleNamespace(policy=None), norm, "ppo")  # type: ignore[arg-type]
    obs = np.random.default_rng(0).normal(scale=50.0, size=(16, 3)).astype(np.float32)
    for _ in range(2):
        assert np.array_equal(policy._normalized(obs), norm.normalize_obs(hold_constant_features(obs, norm)))
    norm.obs_rms.update(np.random.default_rng(1).normal(size=(8, 3)))  # new mean and var arrays
    norm.clip_obs = 2.0
    assert np.array_equal(policy._normalized(obs), norm.normalize_obs(hold_constant_features(obs, norm)))
    assert np.abs(policy._normalized(obs)).max() == 2.0
