"""A recurrent tuner (ppo_lstm) keeps its LSTM state within an episode in SB3Policy.act and forgets it at
begin_episode; predict treats every row as a first step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from sb3_contrib import RecurrentPPO

from bboxtune import envs  # noqa: F401  (registers the ids)
from bboxtune.agents.training.runs import SB3Policy


def test_state_is_carried_within_an_episode_and_reset_between() -> None:
    env = gym.make("bboxtune/FilterRetune-v0", track_length=200)
    model = RecurrentPPO("MlpLstmPolicy", env, seed=0, device="cpu", policy_kwargs={"lstm_hidden_size": 8})
    policy = SB3Policy(model, None, "ppo_lstm", recurrent=True)
    obs, _ = env.reset(options={"noise_seed": 0})
    policy.begin_episode()
    first, second = policy.act(obs, env), policy.act(obs, env)
    assert not np.allclose(first, second)  # same observation, but the memory moved on
    policy.begin_episode()
    np.testing.assert_array_equal(policy.act(obs, env), first)
    np.testing.assert_allclose(policy.predict(np.stack([obs, obs])), np.stack([first, first]), rtol=1e-6)
