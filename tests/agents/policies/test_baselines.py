"""Baselines: the rule reproduces the env's rule, the oracle is never worse, the fitted ones are sane."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune.agents.episodes import EpisodeBank
from bboxtune.agents.policies.baselines import (
    AmortisedPolicy,
    GlobalPolicy,
    GridSearch,
    OraclePolicy,
    RuleEstimatedSigmaPolicy,
    RulePolicy,
    RuleTrueSigmaPolicy,
)
from bboxtune.agents.splits import eval_seeds

SEEDS = eval_seeds("val", 4)


def test_rule_action_reproduces_the_rule_exactly(env: gym.Env) -> None:
    for seed in SEEDS:
        obs, _ = env.reset(options={"noise_seed": int(seed)})
        _, reward, _, _, info = env.step(RulePolicy().act(obs, env))
        assert reward == 0.0 and info["rmse"] == info["rule_rmse"] and info["params"] == info["rule_params"]


def test_oracle_never_worse_than_rule_or_informed_rule(env: gym.Env) -> None:
    policies = [RulePolicy(), RuleTrueSigmaPolicy(), RuleEstimatedSigmaPolicy()]
    oracle = OraclePolicy(GridSearch(budget=30, rounds=1), anchors=policies)
    for seed in SEEDS:
        obs, _ = env.reset(options={"noise_seed": int(seed)})
        r = env.unwrapped.score(np.stack([oracle.act(obs, env), *(p.act(obs, env) for p in policies)]))["reward"]
        assert r[0] >= 0.0 and r[0] >= r[1] and r[0] >= r[2]


def test_oracle_of_another_objective_is_best_on_that_objective(env: gym.Env) -> None:
    search, anchors = GridSearch(budget=30, rounds=1), [RulePolicy(), RuleEstimatedSigmaPolicy()]
    by_reward, by_auc = OraclePolicy(search, anchors), OraclePolicy(search, anchors, objective="success_auc", name="a")
    by_rmse = OraclePolicy(search, anchors, objective="rmse", name="r")
    for seed in SEEDS:
        obs, _ = env.reset(options={"noise_seed": int(seed)})
        actions = np.stack([by_reward.act(obs, env), by_auc.act(obs, env), by_rmse.act(obs, env),
                            *(p.act(obs, env) for p in anchors)])
        s = env.unwrapped.score(actions)
        assert s["success_auc"][1] >= max(s["success_auc"][3:])  # the anchors are candidates
        assert s["rmse"][2] == s["rmse"][0] <= min(s["rmse"][3:])  # the env's reward is the RMSE log-ratio
    with pytest.raises(ValueError, match="objective"):
        OraclePolicy(search, objective="iou")


def test_rule_true_sigma_uses_the_scenario(env: gym.Env) -> None:
    obs, _ = env.reset(options={"noise_seed": 5})
    meta = {**env.unwrapped.episode.meta, **env.unwrapped.episode.scenario}  # tau; the true ψ, σ
    params = env.unwrapped.score(RuleTrueSigmaPolicy().act(obs, env)[None])["params"]
    assert params["psi"][0] == pytest.approx(meta["psi"])
    if "sigma_w" in env.unwrapped.action_map.tune:  # kf_cmn: σ_w and σ_v = σ_ξ are set too
        assert params["sigma_w"][0] == pytest.approx(meta["sigma_w"]) and params["sigma_v"][0] == pytest.approx(meta["sigma_xi"])
    else:  # ufir_cmn: the rule's horizon from the true σ
        from bboxtune.filters.horizon import rule_horizon
        assert params["horizon"][0] == rule_horizon(meta["sigma_xi"], meta["sigma_w"], meta["tau"], 2, max_horizon=400)


def test_grid_search_finds_the_peak_of_a_smooth_surface() -> None:
    peak = np.array([0.37, -0.61])
    best, value = GridSearch(budget=100, rounds=3).search(lambda a: {"reward": -((a - peak) ** 2).sum(axis=1)}, d=2)
    np.testing.assert_allclose(best, peak, atol=0.03)
    assert value > -1e-3


@pytest.mark.parametrize("baseline", ["rule", "raw"])
def test_bank_scores_equal_the_env_scores(env: gym.Env, baseline: str) -> None:
    if baseline == "raw":
        env = gym.make(env.spec.id, **{**env.spec.kwargs, "reward_baseline": "raw"})
    bank = EpisodeBank(env, SEEDS[:2])
    actions = np.random.default_rng(0).uniform(-1, 1, (5, env.action_space.shape[0]))
    for i, seed in enumerate(SEEDS[:2]):
        env.reset(options={"noise_seed": int(seed)})
        ref = env.unwrapped.score(actions)
        got = bank.score(i, actions)
        for key in ("reward", "rmse", "success_auc", "precision20"):
            np.testing.assert_array_equal(got[key], ref[key])


def test_global_fit_beats_the_centre_on_its_training_episodes(env: gym.Env) -> None:
    bank = EpisodeBank(env, eval_seeds("val", 12))
    policy = GlobalPolicy.fit(bank, n_trials=16, batch=8, seed=0)
    d = env.action_space.shape[0]
    assert policy.action.shape == (d,) and np.all(np.abs(policy.action) <= 1)
    best, centre = bank.mean_reward(np.stack([policy.action, np.zeros(d)]))
    assert best >= centre  # the centre is the first trial
    np.testing.assert_array_equal(policy.predict(np.zeros((3, 20))), np.tile(policy.action, (3, 1)))


def test_amortised_learns_a_simple_mapping() -> None:
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(600, 5))
    targets = np.tanh(np.stack([obs[:, 0], -0.5 * obs[:, 1]], axis=1))
    policy = AmortisedPolicy.fit(obs, targets, hidden=(32,), seed=0)
    pred = policy.predict(obs[:100])
    assert np.all(np.abs(pred) <= 1) and np.mean(np.abs(pred - targets[:100])) < 0.1


def test_oracle_targets_are_the_oracle_actions(env: gym.Env) -> None:
    bank = EpisodeBank(env, SEEDS[:2])
    oracle = OraclePolicy(GridSearch(budget=16, rounds=1), anchors=[RulePolicy(), RuleEstimatedSigmaPolicy()])
    targets = AmortisedPolicy.oracle_targets(bank, oracle)
    for i, seed in enumerate(SEEDS[:2]):
        obs, _ = env.reset(options={"noise_seed": int(seed)})
        np.testing.assert_allclose(targets[i], oracle.act(obs, env))
