"""bboxtune.agents.evaluation.regime_informed: the true schedule around the coming window, in the observation of a
reference regressor,
and the best action per true regime state."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs  # noqa: F401  (registers the ids)
from bboxtune.agents.evaluation.regime_informed import (
    CHUNKS,
    PER_CHUNK,
    REGIME_FEATURE_NAMES,
    RegimeInformedPolicy,
    RegimeObservation,
    RegimeOracle,
    regime_features,
    regime_states,
)
from bboxtune.agents.evaluation.retune_eval import RetuneMethod, window_oracle
from bboxtune.agents.evaluation.window_regressor import WindowRegressorSettings, candidate_grid
from bboxtune.agents.policies.baselines import GridSearch
from bboxtune.agents.splits import split_seeds
from bboxtune.envs.episodes.scoring import score_estimates

W = 20
KW = dict(scenario="nonstationary", track_length=200, window=W)


def _chunk(features: np.ndarray, k: int) -> dict[str, float]:
    """Chunk k (−CHUNKS + 1 … 0, 0 the coming window) of the features, by name."""
    i = (k + CHUNKS - 1) * len(PER_CHUNK)
    return dict(zip(PER_CHUNK, features[i:i + len(PER_CHUNK)], strict=False))


def test_features_follow_the_true_schedule_window_by_window() -> None:
    env = gym.make("bboxtune/FilterRetune-v0", **KW)
    for seed in split_seeds("test", 6):
        env.reset(options={"noise_seed": int(seed)})
        base = env.unwrapped
        ep = base.episode
        while base.window_start < len(ep.y):
            start = base.window_start
            f = regime_features(base)
            assert f.shape == (len(REGIME_FEATURE_NAMES),) and f.dtype == np.float32
            coming = _chunk(f, 0)
            part = slice(start, min(start + W, len(ep.y)))
            # gaps are the only missing measurements of a nonstationary sim track
            assert coming["gap"] == pytest.approx(np.isnan(ep.y[part]).all(axis=1).mean())
            psi = np.concatenate([[r["psi"]] * (r["end"] - r["start"]) for r in ep.scenario["regimes"]])
            assert coming["psi"] == pytest.approx(psi[part].mean(), rel=1e-6)
            for k in range(1 - CHUNKS, 1):  # a stretch before frame 0 is marked out of the track, all zeros
                inside = start + (k + 1) * W > 0
                assert _chunk(f, k)["in_track"] == float(inside)
                if not inside:
                    assert not np.any(list(_chunk(f, k).values()))
            assert f[-2] == pytest.approx(np.log(ep.scenario["sigma_w"]), rel=1e-6)
            env.step(env.action_space.sample())


def test_an_episode_without_a_schedule_is_refused() -> None:
    env = gym.make("bboxtune/FilterRetune-v0", track_length=200, window=W)  # stationary
    env.reset(options={"noise_seed": 3})
    with pytest.raises(ValueError, match="scenario='nonstationary'"):
        regime_features(env.unwrapped)


def test_fitted_on_the_wrapped_env_and_asked_with_the_plain_observation() -> None:
    """The fit sees observation + schedule (RegimeObservation); at test the policy appends the schedule itself, so
    every method of a comparison plays the same unwrapped env."""
    plain = gym.make("bboxtune/FilterRetune-v0", **KW)
    wrapped = RegimeObservation(gym.make("bboxtune/FilterRetune-v0", **KW))
    assert wrapped.observation_space.shape[0] == plain.observation_space.shape[0] + len(REGIME_FEATURE_NAMES)
    policy = RegimeInformedPolicy.fit(wrapped, split_seeds("train", 12), settings=WindowRegressorSettings(ensemble=1))
    obs, _ = plain.reset(options={"noise_seed": int(split_seeds("test", 1)[0])})
    action = policy.act(obs, plain)
    assert any(np.array_equal(action, c) for c in policy.candidates)
    wrapped_obs, _ = wrapped.reset(options={"noise_seed": int(split_seeds("test", 1)[0])})
    assert np.array_equal(policy.predict(wrapped_obs[None])[0], action)
    with pytest.raises(ValueError, match="pass env="):
        policy.act(obs)


def test_regime_states_number_noise_regime_manoeuvre_and_gap() -> None:
    schedule = {"regimes": [{"start": 0, "end": 6}, {"start": 6, "end": 10}], "manoeuvres": [[2, 7]], "gaps": [[4, 5], [9, 10]]}
    assert regime_states(schedule, 10).tolist() == [0, 0, 2, 2, 3, 2, 6, 4, 4, 5]
    with pytest.raises(ValueError, match="nonstationary"):
        regime_states({"psi": 0.5}, 10)


def _track_rmse(env: gym.Env, method: RetuneMethod, seed: int) -> float:
    """The RMSE over the frames after the warm-up of ``method`` played on episode ``seed``."""
    obs, _ = env.reset(options={"noise_seed": seed})
    method.play(env, obs)
    base = env.unwrapped
    return float(score_estimates(base.estimates[None, W:], base.episode.truth[W:])["rmse"][0])


def test_the_regime_oracle_lies_between_the_best_single_action_and_the_per_window_oracle() -> None:
    """ufir_cmn: a window's estimates do not depend on earlier windows' parameters, so with the same candidates (a grid
    and the rule's action, no refinement) the best action per regime state is never worse than the best single grid
    action for the track (one action for every state is a choice it has), and the greedy per-window oracle never
    worse than it (it chooses among the same candidates in every window)."""
    env = gym.make("bboxtune/FilterRetune-v0", **KW)
    search = GridSearch(budget=25, rounds=0)
    grid = candidate_grid(env.unwrapped.action_map.dim, search.budget)
    gained = []
    for seed in (int(s) for s in split_seeds("test", 5)):
        env.reset(options={"noise_seed": seed})
        single = float(np.nanmin(env.unwrapped.score_rest(grid)["rmse"]))
        regime = _track_rmse(env, RegimeOracle(search), seed)
        per_window = _track_rmse(env, window_oracle(search), seed)
        assert per_window <= regime * (1 + 1e-9) and regime <= single * (1 + 1e-9)
        assert _track_rmse(env, RegimeOracle(GridSearch(budget=25)), seed) <= regime * (1 + 1e-9)  # refined: no worse
        gained.append(np.log(single / regime))
    assert np.mean(gained) > 0.01  # the regimes change the right action: knowing them pays
