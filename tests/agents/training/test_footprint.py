"""The training run's memory estimate (``bboxtune.agents.training.footprint``): SB3's buffers exactly as SB3 allocates
them, and the refusal at its edge against a pinned available figure."""

from __future__ import annotations

import gymnasium as gym
import pytest

from bboxtune.agents.training.algos import algo_class
from bboxtune.agents.training.footprint import SUBPROCESS_BYTES, buffer_bytes, check_training_memory, env_bytes
from bboxtune.agents.training.hyperparams import constructor_kwargs, load_hyperparams
from bboxtune.agents.training.runs import make_vec
from bboxtune.envs.data import memory
from bboxtune.envs.data.memory import MemoryLimitError
from bboxtune.envs.vector import batch_bytes

TUNE = "bboxtune/FilterTune-v0"
KWARGS = {"backend": "ufir_cmn", "track_length": 50}
ROLLOUT = ("observations", "actions", "rewards", "returns", "episode_starts", "values", "log_probs", "advantages")
LSTM_STATES = ("hidden_states_pi", "cell_states_pi", "hidden_states_vf", "cell_states_vf")
REPLAY = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


@pytest.mark.parametrize(("algo", "overrides", "arrays", "factor"), [
    ("ppo", {"n_envs": 4, "n_steps": 16, "batch_size": 32}, ROLLOUT, 2),  # held twice while training flattens it
    ("a2c", {"n_envs": 2}, ROLLOUT, 2),  # A2C's n_steps: SB3's default (5)
    ("ppo_lstm", {"n_envs": 2, "n_steps": 16, "batch_size": 32, "vec_env": "dummy"}, ROLLOUT + LSTM_STATES, 2),
    ("sac", {"buffer_size": 1000}, REPLAY, 1),
])
def test_the_buffer_estimate_is_what_sb3_allocates(algo, overrides, arrays, factor):
    hp = load_hyperparams(algo, TUNE, overrides)
    venv = make_vec(TUNE, KWARGS, split="train", n_envs=hp.n_envs, seed=0,
                    vec_env="batched" if hp.vec_env == "batched" else "dummy")
    n_actions = venv.action_space.shape[0]
    model = algo_class(algo)(hp.policy, venv, device="cpu", **constructor_kwargs(hp, n_actions))
    buffer = model.rollout_buffer if factor == 2 else model.replay_buffer
    allocated = sum(getattr(buffer, name).nbytes for name in arrays)
    assert buffer_bytes(hp, venv.observation_space.shape[0], n_actions) == factor * allocated
    venv.close()


def test_env_bytes_counts_the_prepared_episodes_and_the_workers():
    env = gym.make(TUNE, **KWARGS, split="train")
    block = env.unwrapped.source.block
    batched, dummy = (load_hyperparams("ppo", TUNE, {"n_envs": 8, "vec_env": v}) for v in ("batched", "dummy"))
    subproc = load_hyperparams("ppo", TUNE, {"n_envs": 8, "vec_env": "subproc"})
    assert env_bytes(batched, env) == batch_bytes(8, 50)
    assert env_bytes(dummy, env) == batch_bytes(8 * block, 50)  # each env prepares a block of episodes
    assert env_bytes(subproc, env) == batch_bytes(8 * block, 50) + 8 * SUBPROCESS_BYTES


@pytest.mark.parametrize(("algo", "overrides", "message"), [
    ("ppo", {"n_envs": 1000}, r"^n_envs=1000 with n_steps=32 \(ppo, vec_env batched\) needs ~"),
    ("sac", {"buffer_size": 10**6}, r"^n_envs=1 with buffer_size=1000000 \(sac, vec_env dummy\) needs ~"),
])
def test_check_training_memory_refuses_beyond_the_available_figure(algo, overrides, message, monkeypatch):
    hp = load_hyperparams(algo, TUNE, overrides)
    env = gym.make(TUNE, **KWARGS, split="train")
    obs_dim, n_actions = env.observation_space.shape[0], env.action_space.shape[0]
    needed = env_bytes(hp, env) + buffer_bytes(hp, obs_dim, n_actions)
    monkeypatch.setattr(memory, "available_bytes", lambda: needed)
    check_training_memory(hp, env)  # exactly what is available
    monkeypatch.setattr(memory, "available_bytes", lambda: needed - 1)
    with pytest.raises(MemoryLimitError, match=message):
        check_training_memory(hp, env)
