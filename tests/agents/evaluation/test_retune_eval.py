"""FilterRetune-v0 evaluation (bboxtune.agents.evaluation.retune_eval, bboxtune.agents.evaluation.report_retune) and the
env pieces it rests on."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs  # noqa: F401  (registers the ids)
from bboxtune.agents.evaluation.report import summary_markdown
from bboxtune.agents.evaluation.report_retune import retune_tables
from bboxtune.agents.evaluation.retune_eval import OneShotLearned, OneShotOracle, Sequential, evaluate_retune, window_oracle
from bboxtune.agents.policies.baselines import GridSearch, ObsPolicy, RulePolicy
from bboxtune.agents.splits import EpisodeSpec
from bboxtune.envs.episodes.features import FEATURE_NAMES, WINDOW_FEATURE_NAMES

RETUNE, TUNE = "bboxtune/FilterRetune-v0", "bboxtune/FilterTune-v0"
SMALL = GridSearch(budget=16, rounds=1)


class Constant(ObsPolicy):
    def __init__(self, action: np.ndarray, name: str) -> None:
        self.action, self.name = np.asarray(action, float), name

    def predict(self, obs: np.ndarray) -> np.ndarray:
        return np.tile(self.action, (len(obs), 1))


@pytest.mark.parametrize("backend", ["kf_cmn", "ufir_cmn", "ofir"])
def test_score_rest_equals_stepping_to_the_end(backend: str) -> None:
    env = gym.make(RETUNE, backend=backend, scenario="nonstationary", track_length=230, window=40)
    base = env.unwrapped
    env.reset(options={"noise_seed": 3})
    d = env.action_space.shape[0]
    env.step(np.full(d, 0.3, np.float32))  # from mid-episode, with a carried state
    actions = np.random.default_rng(0).uniform(-1, 1, (3, d))
    rest = base.score_rest(actions)
    start = base.estimates.shape[0] - rest["estimates"].shape[1]
    for a, est, rmse in zip(actions, rest["estimates"], rest["rmse"], strict=False):
        env.reset(options={"noise_seed": 3})
        env.step(np.full(d, 0.3, np.float32))
        done = False
        while not done:
            *_, done, _, _ = env.step(a.astype(np.float32))
        np.testing.assert_allclose(base.estimates[start:], est, rtol=0, atol=1e-5)  # px; FIR rounding differs by start
        sq = np.sum((base.estimates[start:] - base.episode.truth[start:]) ** 2, axis=1)  # per frame, 4 coordinates
        assert rmse == pytest.approx(np.sqrt(np.mean(sq)), rel=1e-6)


def test_observation_carries_the_window_residuals() -> None:
    env = gym.make(RETUNE, backend="ufir_cmn", track_length=300)
    d = env.action_space.shape[0]
    obs, _ = env.reset(options={"noise_seed": 1})
    assert obs.shape == (len(FEATURE_NAMES) + len(WINDOW_FEATURE_NAMES) + d + 1,) == env.observation_space.shape
    w = slice(len(FEATURE_NAMES), len(FEATURE_NAMES) + len(WINDOW_FEATURE_NAMES))
    assert abs(obs[w][2]) < 1e-9  # after the warm-up the filter is the rule
    smooth, _, _, _, _ = env.step(np.array([1.0, -1.0], np.float32))  # longest horizon, ψ = 0
    env.reset(options={"noise_seed": 1})
    rough, _, _, _, _ = env.step(np.array([-1.0, -1.0], np.float32))  # N = 2: the measurements themselves
    assert rough[w][0] < smooth[w][0] and rough[w][2] < 0 < smooth[w][2]
    assert np.isfinite(obs).all() and np.isfinite(rough).all()


def test_methods_on_the_same_episodes() -> None:
    env = gym.make(RETUNE, backend="ufir_cmn", scenario="nonstationary", track_length=200)
    tune_env = gym.make(TUNE, backend="ufir_cmn", scenario="nonstationary", track_length=200)
    methods = [Sequential(RulePolicy()), OneShotOracle(SMALL), OneShotLearned(Constant([0.5, 0.0], "c"), tune_env),
               window_oracle(SMALL), Sequential(Constant([0.5, 0.0], "ppo"))]
    episodes = [EpisodeSpec(1_000_000_000 + i) for i in range(4)]
    result = evaluate_retune(env, methods, episodes)
    rows = {(r["method"], r["episode"]): r for r in result.rows}
    names = ["raw", "rule", "oneshot_oracle", "oneshot_learned", "window_oracle", "ppo", "adaptive", "imm"]
    assert sorted({m for m, _ in rows}) == sorted(names)
    for e in range(4):
        assert rows["rule", e]["log_ratio"] == 0.0
        assert rows["oneshot_oracle", e]["rmse"] <= rows["rule", e]["rmse"] + 1e-9  # the rule is a candidate
        assert rows["oneshot_learned", e]["rmse"] == pytest.approx(rows["ppo", e]["rmse"])  # same constant action
        assert rows["window_oracle", e]["scored_from"] == 50
    assert result.truth_at_test["window_oracle"].startswith("y") and result.truth_at_test["ppo"] == "n"
    sched = result.example["schedules"]["window_oracle"]
    assert [w for w, _ in sched] == [(50, 100), (100, 150), (150, 200)]
    lines = retune_tables(result.rows, ["ppo"], n_boot=50)
    text = "\n".join(lines)
    assert "gap closed" in text and "| oneshot_oracle | " in text and "Paired: sequential against oneshot_learned" in text
    oracle_row = next(line for line in text.splitlines() if line.startswith("| window_oracle |"))
    assert "+1.00 [+1.00, +1.00]" in oracle_row
    summary = summary_markdown(result.rows, result.truth_at_test, learned=["ppo"], title="t", settings={}, figures=[],
                               n_boot=50, rmse_oracle="window_oracle")
    assert "regret = mean log(RMSE / RMSE_window_oracle)" in summary


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn"])
@pytest.mark.parametrize("reward", ["rmse", "success_auc"])
def test_track_rewards_add_up_to_the_tracks_reward(backend: str, reward: str) -> None:
    """retune_reward="track" (default): the returns of an episode are its whole reward after the warm-up, so
    the sequential objective is the evaluation's metric; "window" keeps each window's own reward."""
    from bboxtune.envs.episodes.scoring import reward_from, score_estimates

    for kind in ("track", "window"):
        env = gym.make(RETUNE, backend=backend, scenario="nonstationary", reward=reward, retune_reward=kind)
        base = env.unwrapped
        env.reset(options={"noise_seed": 4})
        rng, total, done, windows = np.random.default_rng(0), 0.0, False, []
        while not done:
            _, r, done, _, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
            total += r
            windows.append(r)
        ep, first = base.episode, 50
        scores = score_estimates(np.stack([base.estimates[first:], base._rule_est[first:]]), ep.truth[first:])
        whole = float(reward_from({k: v[:1] for k, v in scores.items()}, {k: float(v[1]) for k, v in scores.items()}, reward)[0])
        if kind == "track":
            assert total == pytest.approx(whole, abs=1e-9)
        else:
            assert total != pytest.approx(whole, abs=1e-6) and len(windows) == 9


def test_window_oracle_wins_every_window_it_chooses() -> None:
    env = gym.make(RETUNE, backend="kf_cmn", scenario="nonstationary", track_length=150, retune_reward="window")
    env.reset(options={"noise_seed": 5})
    rewards, done = [], False
    oracle = window_oracle(SMALL).policy
    obs = None
    while not done:
        obs, reward, done, _, _ = env.step(oracle.act(obs, env))
        rewards.append(reward)
    assert min(rewards) >= -1e-12  # the rule's action is a candidate in every window
