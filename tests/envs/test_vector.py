"""The batched FilterTune-v0 (envs/vector.py): the Gymnasium VectorEnv face, its equality with the single env on
the same episodes, seeding, and its refusals."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs
from bboxtune.envs.vector import TuneBatch, TuneVectorEnv
from tests.envs.conftest import OTB_ROOT, needs_otb

TUNE = "bboxtune/FilterTune-v0"
SHORT = {"track_length": 120}


def _single_steps(kwargs: dict, tracks: list[dict], actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """Observations, rewards and step infos of the single env on the pinned episodes ``tracks``."""
    env = gym.make(TUNE, **kwargs)
    obs, rewards, infos = [], [], []
    for track, action in zip(tracks, actions, strict=False):
        pins = {k: track[k] for k in ("sequence", "noise_seed", "tracker") if track.get(k) is not None}
        o, _ = env.reset(options=pins)
        _, r, *_, info = env.step(action)
        obs.append(o), rewards.append(r), infos.append(info)
    return np.stack(obs), np.array(rewards), infos


def _tracks(infos: dict, n: int) -> list[dict]:
    """The per-env ``track`` dicts of a vector env's merged infos."""
    return [{k: infos["track"][k][i] for k in infos["track"] if not k.startswith("_")} for i in range(n)]


@pytest.mark.parametrize("backend, extra", [("ufir_cmn", {}), ("kf_cmn", {}), ("oufir", {}),
                                            ("ufir_cmn", {"reward_baseline": "raw", "reward": "success_auc"})])
def test_a_batched_step_equals_the_single_env_on_the_same_episodes(backend: str, extra: dict) -> None:
    kwargs = {"backend": backend, **SHORT, **extra}
    venv = envs.make_vec(TUNE, 5, **kwargs)
    assert isinstance(venv, TuneVectorEnv) and venv.num_envs == 5
    obs, infos = venv.reset(seed=3)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (5, venv.single_action_space.shape[0])).astype(np.float32)
    next_obs, rewards, terminated, truncated, step = venv.step(actions)
    assert terminated.all() and not truncated.any() and next_obs.shape == obs.shape
    single_obs, single_rewards, single_infos = _single_steps(kwargs, _tracks(infos, 5), actions)
    np.testing.assert_allclose(obs, single_obs, rtol=1e-6)
    np.testing.assert_allclose(rewards, single_rewards, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(np.stack(step["final_obs"]), obs)  # the finished episodes' observations
    for key in ("rmse", "rule_rmse", "success_auc"):
        np.testing.assert_allclose(step["final_info"][key], [i[key] for i in single_infos], rtol=1e-9)
    assert not np.array_equal(next_obs, obs)  # auto-reset: new episodes in the same step


def test_the_same_seed_gives_the_same_episodes_and_another_seed_others() -> None:
    venv = envs.make_vec(TUNE, 3, backend="ufir_cmn", **SHORT)
    first = venv.reset(seed=7)[0]
    assert np.array_equal(venv.reset(seed=7)[0], first)
    assert np.array_equal(venv.reset(seed=[7, 8, 9])[0], first)  # a list: its first entry seeds the batch
    assert not np.array_equal(venv.reset(seed=8)[0], first)


def test_noise_seeds_come_from_the_given_sampler() -> None:
    batch = TuneBatch(4, lambda rng, n: np.arange(100, 100 + n), backend="ufir_cmn", **SHORT)
    _, infos = batch.reset()
    assert [i["track"]["noise_seed"] for i in infos] == [100, 101, 102, 103]


def test_make_vec_of_the_retune_env_is_gymnasiums_sync_vector_env() -> None:
    venv = envs.make_vec("bboxtune/FilterRetune-v0", 2, backend="ufir_cmn", **SHORT)
    assert isinstance(venv, gym.vector.SyncVectorEnv)
    assert venv.reset(seed=0)[0].shape[0] == 2


@pytest.mark.parametrize("call, error, match", [
    (lambda v: v.step(np.zeros((3, 2), np.float32)), RuntimeError, "reset"),
    (lambda v: (v.reset(), v.step(np.zeros((2, 2), np.float32))), ValueError, r"allowed \(3, 2\)"),
    (lambda v: (v.reset(), v.step(np.zeros(2, np.float32))), ValueError, r"allowed \(3, 2\)"),
    (lambda v: (v.reset(), v.step(np.full((3, 2), 1.5))), ValueError, "out of range"),
    (lambda v: (v.reset(), v.step(np.full((3, 2), np.nan))), ValueError, "NaN"),
    (lambda v: v.reset(options={"noise_seed": 1}), ValueError, "reset options"),
])
def test_bad_calls_are_refused(call, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        call(envs.make_vec(TUNE, 3, backend="ufir_cmn", **SHORT))


@pytest.mark.parametrize("kwargs, error, match", [
    ({"num_envs": 0}, ValueError, "n_envs=0"),
    ({"num_envs": 2, "render_mode": "rgb_array"}, TypeError, "render_mode"),
    ({"num_envs": 2, "track_length": 1}, ValueError, "track_length"),
    ({"num_envs": 2, "colour": 1}, TypeError, "colour"),
])
def test_bad_arguments_are_refused(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        TuneVectorEnv(**{"backend": "ufir_cmn", **kwargs})


@needs_otb
def test_otb_tracks_of_different_lengths_batch_together() -> None:
    kwargs = {"backend": "ufir_cmn", "source": "otb", "otb_root": OTB_ROOT}
    venv = envs.make_vec(TUNE, 4, **kwargs)
    obs, infos = venv.reset(seed=1)
    actions = np.zeros((4, 2), np.float32)
    _, rewards, _, _, step = venv.step(actions)
    assert len(set(step["final_info"]["n_frames"].tolist())) > 1  # sequences of different lengths in one batch
    _, single_rewards, _ = _single_steps(kwargs, _tracks(infos, 4), actions)
    np.testing.assert_allclose(rewards, single_rewards, rtol=1e-9, atol=1e-12)
