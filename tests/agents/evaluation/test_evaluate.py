"""bboxtune.agents.evaluation.evaluate: which episodes are scored, and the raw measurements as a method of their own."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune.agents.evaluation.evaluate import evaluate, evaluation_episodes, standard_policies
from bboxtune.agents.policies.baselines import GridSearch, RulePolicy
from bboxtune.agents.splits import EpisodeSpec, eval_seeds, split_seeds
from bboxtune.envs.episodes.scoring import score_estimates

from ..conftest import ENV_ID, SHORT


def test_sim_episodes_are_split_seeds_and_otb_flags_are_refused() -> None:
    env = gym.make(ENV_ID, **SHORT, split="val")
    assert evaluation_episodes(env, "val", episodes=4, seeds_per_sequence=None) == [EpisodeSpec(int(s)) for s in
                                                                                     eval_seeds("val", 4)]
    assert [e.noise_seed for e in evaluation_episodes(env, "val", episodes=4, seeds_per_sequence=None, seed=2)] == \
        list(split_seeds("val", 4, 2))
    for kwargs in ({"episodes": None, "seeds_per_sequence": None}, {"episodes": 4, "seeds_per_sequence": 2}):
        with pytest.raises(ValueError, match="draws its episodes"):
            evaluation_episodes(env, "val", **kwargs)


def test_the_second_oracle_is_of_the_other_metric() -> None:
    names = lambda reward, source="otb", backend="ufir_cmn": [  # noqa: E731
        p.name for p in standard_policies(source, GridSearch(budget=9), reward, backend=backend)]
    assert names("rmse") == ["rule", "rule_est_sigma", "oracle", "oracle_auc"]
    assert names("success_auc")[-2:] == ["oracle", "oracle_rmse"] and names("iou_precision")[-1] == "oracle_rmse"
    assert names("rmse", "sim") == ["rule", "rule_est_sigma", "rule_true_sigma", "oracle", "oracle_auc"]
    # bytetrack_kf's weights have no σ rule: its rule (stock ByteTrack) anchors the oracles alone
    assert names("rmse", "sim", "bytetrack_kf") == ["rule", "oracle", "oracle_auc"]


def test_raw_scores_the_measurements_and_missing_ones_as_missing_estimates() -> None:
    env = gym.make(ENV_ID, **SHORT)
    result = evaluate(env, [RulePolicy()], [EpisodeSpec(7)], adaptive=None)
    env.reset(options={"noise_seed": 7})
    ep = env.unwrapped.episode
    raw = next(r for r in result.rows if r["method"] == "raw")
    assert raw["rmse"] == score_estimates(ep.y[None], ep.truth)["rmse"][0] and np.isnan(raw["param_horizon"])
    y = ep.y.copy()
    y[10:20] = np.nan  # a tracker that lost the target for 10 frames
    gaps = score_estimates(y[None], ep.truth)
    full = score_estimates(ep.y[None], ep.truth)
    assert gaps["success_auc"][0] < full["success_auc"][0] and np.isfinite(gaps["rmse"][0])
    with pytest.raises(ValueError, match="distinct"):
        named = RulePolicy()
        named.name = "raw"
        evaluate(env, [RulePolicy(), named], [EpisodeSpec(7)])
