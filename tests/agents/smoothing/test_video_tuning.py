"""Tuned filters for video episodes: the grid search, tuned.json round trip, the trained-policy hook."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from bboxtune.agents.policies.baselines import GlobalPolicy
from bboxtune.agents.smoothing.video_tuning import EpisodeTuner, action_map, fixed_tuner, grid_tune, load_tuner
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.scoring import run_positions, score_estimates
from bboxtune.envs.episodes.video_source import VideoSettings, VideoSource


@pytest.fixture(scope="module")
def episodes():
    src = VideoSource(EnvConfig(split="train", track_length=40),
                      VideoSettings(detector="regions", video_pool=2, video_size=(128, 96)))
    return [src.draw(name, 0) for name in src.names]


def mean_auc(episodes, backend, action):
    amap = action_map(backend)
    return np.mean([score_estimates(run_positions(backend, ep.y, ep.tau, amap.to_params(action, ep.nominal)),
                                    ep.truth)["success_auc"][0] for ep in episodes])


def test_grid_tune_returns_the_best_grid_point(episodes):
    tuner, best = grid_tune(episodes, "kf", points=3)
    grid = list(itertools.product([-1.0, 0.0, 1.0], repeat=2))
    brute = [mean_auc(episodes, "kf", np.array(a)) for a in grid]
    assert best == pytest.approx(max(brute))
    assert isinstance(tuner.policy, GlobalPolicy)  # one tuner hierarchy: the fixed action is the baselines' global
    assert mean_auc(episodes, "kf", tuner.policy.action) == pytest.approx(max(brute))
    assert tuner.policy.action.tolist() in [list(a) for a, s in zip(grid, brute, strict=False) if s == max(brute)]


def test_tuned_json_round_trip(tmp_path, episodes):
    tuner = fixed_tuner("ufir_cmn", np.array([0.5, -0.25]))
    (tmp_path / "tuned.json").write_text(json.dumps(tuner.document(detector="regions")))
    loaded = load_tuner(tmp_path)  # a folder holding tuned.json
    assert loaded.backend == "ufir_cmn" and loaded.actions.tune == ("psi", "horizon")
    for key, value in tuner.params(episodes[0]).items():
        np.testing.assert_array_equal(loaded.params(episodes[0])[key], value)


def test_policy_tuner_feeds_env_features_to_the_policy(episodes):
    class Zero:
        seen = None

        def predict(self, obs):
            Zero.seen = obs
            return np.zeros((len(obs), 2))

    EpisodeTuner(Zero(), "kf", action_map("kf"), msd=True).params(episodes[0])  # a run of the "msd" feature set
    assert Zero.seen.shape == (1, 21) and np.all(np.isfinite(Zero.seen))
    tuner = EpisodeTuner(Zero(), "kf", action_map("kf"))
    params = tuner.params(episodes[0])
    assert Zero.seen.shape == (1, 20) and np.all(np.isfinite(Zero.seen))
    np.testing.assert_allclose(params["sigma_w"], episodes[0].nominal.sigma_w)  # action 0 = nominal σ
    with pytest.raises(TypeError, match="only a fixed action"):
        tuner.document()


def test_load_tuner_rejects_other_paths(tmp_path):
    with pytest.raises(ValueError, match="neither"):
        load_tuner(tmp_path)
    (tmp_path / "bad.json").write_text('{"backend": "kf"}')
    with pytest.raises(ValueError, match="missing key"):
        load_tuner(tmp_path / "bad.json")
