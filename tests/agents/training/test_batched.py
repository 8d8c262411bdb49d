"""agents/training/batched.py: the SB3 VecEnv over the batched FilterTune-v0, and how training selects it."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from bboxtune.agents.splits import RESERVED
from bboxtune.agents.training.batched import TuneVecEnv
from bboxtune.agents.training.hyperparams import load_hyperparams
from bboxtune.agents.training.runs import make_vec

TUNE, RETUNE = "bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"
SHORT = {"backend": "ufir_cmn", "track_length": 120}


def test_steps_end_every_episode_and_report_it_as_monitor_does() -> None:
    venv = make_vec(TUNE, SHORT, split="train", n_envs=4, seed=0, vec_env="batched")
    assert isinstance(venv, TuneVecEnv)
    obs = venv.reset()
    seeds = [i["track"]["noise_seed"] for i in venv.reset_infos]
    assert not any(RESERVED[0] <= s < RESERVED[1] for s in seeds)  # train-split noise seeds
    new_obs, rewards, dones, infos = venv.step(np.zeros((4, 2), np.float32))
    assert dones.all() and rewards.dtype == np.float32 and new_obs.shape == obs.shape
    for i, info in enumerate(infos):
        np.testing.assert_array_equal(info["terminal_observation"], obs[i])
        assert info["episode"]["l"] == 1 and info["episode"]["r"] == pytest.approx(rewards[i])
        assert info["TimeLimit.truncated"] is False and "rule_rmse" in info
    assert venv.get_attr("config")[0].backend == "ufir_cmn" and len(venv.get_attr("config", indices=[0, 1])) == 2


def test_seeding_reproduces_the_episodes() -> None:
    a = make_vec(TUNE, SHORT, split="train", n_envs=3, seed=5, vec_env="batched")
    b = make_vec(TUNE, SHORT, split="train", n_envs=3, seed=5, vec_env="batched")
    np.testing.assert_array_equal(a.reset(), b.reset())
    a.seed(9)
    assert not np.array_equal(a.reset(), b.reset())


def test_ppo_trains_on_it_under_vecnormalize() -> None:
    venv = VecNormalize(make_vec(TUNE, SHORT, split="train", n_envs=8, seed=0, vec_env="batched"), norm_reward=False)
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(128)
    assert model.num_timesteps == 128 and len(model.ep_info_buffer) > 0


@pytest.mark.parametrize("env_id, split", [(TUNE, "val"), (RETUNE, "train")])
def test_only_the_train_split_of_filtertune_is_batched(env_id: str, split: str) -> None:
    with pytest.raises(ValueError, match="vec_env='batched' serves the train split"):
        make_vec(env_id, SHORT, split=split, n_envs=2, seed=0, vec_env="batched")


def test_options_and_set_attr_are_refused() -> None:
    venv = make_vec(TUNE, SHORT, split="train", n_envs=2, seed=0, vec_env="batched")
    venv.set_options({"noise_seed": 3})
    with pytest.raises(ValueError, match="reset options"):
        venv.reset()
    with pytest.raises(AttributeError, match="share one configuration"):
        venv.set_attr("config", None)


def test_the_ppo_file_batches_filtertune_and_runs_other_envs_in_subprocesses() -> None:
    assert load_hyperparams("ppo", TUNE).vec_env == "batched"
    retune = load_hyperparams("ppo", RETUNE)
    assert retune.vec_env == "subproc" and retune.raw["vec_env"] == "subproc"  # the file's batched, where the env has none
    assert load_hyperparams("ppo", RETUNE, retune.raw).vec_env == "subproc"  # a run's config.yml loads again (resume)
    with pytest.raises(ValueError, match="vec_env='batched' exists for"):
        load_hyperparams("ppo", RETUNE, {"vec_env": "batched"})
