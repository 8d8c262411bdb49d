"""backend="bytetrack_kf" in FilterTune-v0 and FilterRetune-v0: its rule is stock ByteTrack (the filter of
``bboxtune.filters.make("bytetrack_kf", model)`` with the published weights), every env path runs it (checkers, score, the
batched env, re-tuning with carried state, MOT15 episodes), and what it refuses."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from bboxtune import envs, filters
from bboxtune.agents.episodes import rule_action
from bboxtune.agents.policies.baselines import (
    GridSearch,
    OraclePolicy,
    RuleEstimatedSigmaPolicy,
    RulePolicy,
    RuleTrueSigmaPolicy,
)
from bboxtune.envs.episodes.actions import BACKENDS, STOCK
from bboxtune.envs.episodes.features import box_scale
from bboxtune.envs.episodes.scoring import box_model, detections

TUNE, RETUNE = envs.TUNE_ID, envs.RETUNE_ID
SIM = {"backend": "bytetrack_kf", "track_length": 64}
ALL = tuple(STOCK)  # the two weights and std_aspect_measurement


def stock(y: np.ndarray, tau: float) -> np.ndarray:
    """Stock ByteTrack (the published defaults) on the boxes the env hands it, (T, 4)."""
    return filters.make("bytetrack_kf", box_model(tau)).positions(detections("bytetrack_kf", y))


@pytest.mark.parametrize("env_id, extra", [(TUNE, {}), (RETUNE, {"window": 16})])
def test_checkers_pass(env_id: str, extra: dict) -> None:
    env = gym.make(env_id, **SIM, **extra)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize("extra", [{}, {"tune": ALL}])
def test_the_rule_is_stock_bytetrack_and_its_action_scores_zero(extra: dict) -> None:
    env = gym.make(TUNE, **SIM, **extra)
    u = env.unwrapped
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        ep = u.episode
        action = rule_action(env)
        np.testing.assert_array_equal(action, np.zeros(len(u.config.tune)))  # stock is the centre of the box
        np.testing.assert_allclose(u.score(action[None])["estimates"][0], stock(ep.y, ep.tau), rtol=1e-12, atol=1e-9)
        _, reward, terminated, _, info = env.step(action.astype(np.float32))
        assert reward == 0.0 and terminated and info["rmse"] == info["rule_rmse"]
        assert info["params"] == info["rule_params"] == STOCK
        assert np.isfinite(obs).all()


def test_score_equals_step_and_the_weights_act_through_their_ratio() -> None:
    env = gym.make(TUNE, **SIM)
    env.reset(seed=9)
    actions = np.array([[-1.0, -1.0], [0.7, 0.7], [-1.0, 1.0], [1.0, -1.0], [0.3, -0.6]], np.float32)
    batch = env.unwrapped.score(actions)
    assert np.isfinite(batch["reward"]).all() and set(batch["params"]) >= set(STOCK)
    for i, a in enumerate(actions):
        env.reset(seed=9)
        _, reward, _, _, info = env.step(a)
        assert reward == pytest.approx(batch["reward"][i], rel=1e-10, abs=1e-12)
        assert info["params"]["std_weight_velocity"] == pytest.approx(1 / 160 * 10 ** (1.5 * float(a[1])), rel=1e-6)
    # one factor on both weights scales Q, R and P0 alike: the same filter (as the rule, a = 0)
    ep = env.unwrapped.episode
    np.testing.assert_allclose(batch["estimates"][:2], np.broadcast_to(stock(ep.y, ep.tau), (2, 64, 4)),
                               rtol=1e-9, atol=1e-9)
    assert batch["reward"][2] != batch["reward"][3]  # their ratio matters


def test_a_batched_step_equals_the_single_env() -> None:
    venv = envs.make_vec(TUNE, 4, **SIM)
    obs, infos = venv.reset(seed=3)
    actions = np.random.default_rng(0).uniform(-1, 1, (4, 2)).astype(np.float32)
    _, rewards, terminated, _, step = venv.step(actions)
    assert terminated.all()
    env = gym.make(TUNE, **SIM)
    for i in range(4):
        single_obs, _ = env.reset(options={"noise_seed": int(infos["track"]["noise_seed"][i])})
        _, reward, *_, info = env.step(actions[i])
        np.testing.assert_allclose(obs[i], single_obs, rtol=1e-6)
        assert rewards[i] == pytest.approx(reward, rel=1e-9, abs=1e-12)
        assert step["final_info"]["rule_rmse"][i] == pytest.approx(info["rule_rmse"], rel=1e-9)


def test_retuning_carries_the_filter_across_windows() -> None:
    env = gym.make(RETUNE, backend="bytetrack_kf", track_length=200, window=50)
    u = env.unwrapped
    obs, _ = env.reset(seed=1)
    assert obs.shape == (20 + 4 + 2 + 1,)
    rewards = []
    for _ in range(3):
        obs, reward, terminated, _, info = env.step(np.zeros(2, np.float32))  # the rule's action in every window
        rewards.append(reward)
    assert terminated and rewards == [0.0] * 3 and info["params"] == STOCK
    # window by window with the state carried over = one stock run over the whole track
    np.testing.assert_allclose(u.estimates, stock(u.episode.y, u.episode.tau), rtol=1e-12, atol=1e-9)
    env.reset(seed=1)
    for a in ([-1.0, 1.0], [0.5, 0.5], [1.0, -1.0]):
        obs, reward, terminated, _, info = env.step(np.array(a, np.float32))
        assert np.isfinite(obs).all() and np.isfinite(reward)
    assert terminated and np.isfinite(info["track_rmse"])


def test_the_mot_source(mot_root: Path) -> None:
    env = gym.make(TUNE, backend="bytetrack_kf", source="mot", mot_root=str(mot_root))
    u = env.unwrapped
    for seed in range(2):
        obs, info = env.reset(seed=seed)
        ep = u.episode
        scores = u.score(np.array([[0.0, 0.0], [-1.0, 1.0], [0.5, -0.5]]))
        np.testing.assert_allclose(scores["estimates"][0], stock(ep.y, ep.tau), rtol=1e-12, atol=1e-9)
        assert scores["reward"][0] == 0.0 and np.isfinite(scores["reward"]).all() and np.isfinite(obs).all()
        _, reward, *_, info = env.step(np.array([-0.5, 0.5], np.float32))
        assert reward == pytest.approx(u.score(np.array([[-0.5, 0.5]], np.float32))["reward"][0], rel=1e-12)
    retune = gym.make(RETUNE, backend="bytetrack_kf", source="mot", mot_root=str(mot_root), window=20)
    retune.reset(seed=0)
    _, reward, *_ = retune.step(np.zeros(2, np.float32))
    assert reward == 0.0


def test_trusting_the_measurement_needs_the_aspect_term() -> None:
    """σ_p at the bottom and σ_ṗ at the top follow cx, cy and h; w = a h keeps stock ByteTrack's smoothing of the aspect
    a unless its measurement std is tuned too (tune=ALL, -1) with sigma_decades=2.5 (FilterTuneEnv, Action Space)."""
    worst = {}
    for name, kwargs in (("default", {}), ("aspect", {"tune": ALL, "sigma_decades": 2.5})):
        env = gym.make(TUNE, backend="bytetrack_kf", track_length=300, tau_range=(1 / 30, 1 / 30), **kwargs)
        u = env.unwrapped
        action = np.array([-1.0, 1.0, -1.0][: len(u.config.tune)], np.float32)
        deviation = []
        for seed in range(4):
            env.reset(options={"noise_seed": seed})
            ep = u.episode
            deviation.append((np.abs(u.score(action[None])["estimates"][0] - ep.y) / box_scale(ep.y)).max(axis=0))
        worst[name] = np.max(deviation, axis=0)  # per coordinate cx, cy, w, h
    assert worst["default"][[0, 1, 3]].max() < 1e-3 and worst["default"][2] > 0.05
    assert worst["aspect"].max() < 1e-3  # 0.1 % of the box scale (the other back ends' tolerance)


def test_boxes_without_a_positive_size_are_no_detections() -> None:
    y = np.array([[50.0, 60.0, 20.0, 40.0], [51.0, 60.0, -0.5, 40.0], [np.nan] * 4, [52.0, 61.0, 22.0, 0.0],
                  [53.0, 61.0, 21.0, 41.0]])
    masked = detections("bytetrack_kf", y)
    assert np.isnan(masked[1:4]).all() and np.array_equal(masked[[0, 4]], y[[0, 4]])
    assert detections("kf_cmn", y) is y and detections("bytetrack_kf", y[[0, 4]]) is not masked
    # small boxes under large noise: measured sizes at or below 0 happen, and the env filters the rest
    env = gym.make(TUNE, **SIM, box_size_range=(4.0, 5.0), sigma_xi_range=(5.0, 10.0))
    env.reset(seed=0)
    found = False
    for _ in range(8):
        obs, _ = env.reset()
        found |= bool((env.unwrapped.episode.y[:, 2:] <= 0).any())
        _, reward, *_, info = env.step(np.array([0.5, -0.5], np.float32))
        assert np.isfinite(obs).all() and np.isfinite(reward) and np.isfinite(info["rmse"])
    assert found


def test_the_oracle_and_the_rule_and_the_sigma_rules_refused() -> None:
    env = gym.make(TUNE, **SIM)
    obs, _ = env.reset(seed=5)
    oracle = OraclePolicy(GridSearch(budget=25, rounds=1), anchors=(RulePolicy(),))
    score = env.unwrapped.score(np.stack([oracle.act(obs, env), RulePolicy().act(obs, env)]))
    assert score["reward"][0] >= score["reward"][1] == 0.0
    for policy in (RuleEstimatedSigmaPolicy(), RuleTrueSigmaPolicy()):
        with pytest.raises(ValueError, match="stock filter"):
            policy.act(obs, env)


def test_arguments() -> None:
    assert "bytetrack_kf" in BACKENDS and gym.make(TUNE, **SIM, tune=ALL).action_space.shape == (3,)
    with pytest.raises(ValueError, match=r"backend='sort_kf'.*'bytetrack_kf'"):
        gym.make(TUNE, backend="sort_kf")
    with pytest.raises(ValueError, match="tune=.*for backend 'bytetrack_kf'.*std_weight_position"):
        gym.make(TUNE, backend="bytetrack_kf", tune=("sigma_w",))
