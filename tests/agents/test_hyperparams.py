"""YAML hyperparameters in the RL Zoo layout, parsed without eval."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch.nn as nn
from stable_baselines3.common.noise import NormalActionNoise

from agents.algos import ALGOS
from agents.hyperparams import constructor_kwargs, load_hyperparams, parse_schedule

from .conftest import ENV_ID


@pytest.mark.parametrize("algo", sorted(ALGOS))
def test_every_algo_has_a_default_for_the_env(algo: str) -> None:
    hp = load_hyperparams(algo, ENV_ID)
    assert hp.n_timesteps > 0 and hp.n_envs >= 1 and hp.policy == "MlpPolicy"
    assert hp.normalize == {"norm_obs": True, "norm_reward": False}


def test_linear_schedule() -> None:
    sched = parse_schedule("lin_3e-4", where="test")
    assert sched(1.0) == pytest.approx(3e-4) and sched(0.5) == pytest.approx(1.5e-4) and sched(0.0) == 0.0
    assert parse_schedule(1e-3, where="test") == 1e-3
    with pytest.raises(ValueError, match="lin_"):
        parse_schedule("exp_1e-3", where="test")


def test_default_and_per_id_override(tmp_path: Path) -> None:
    (tmp_path / "ppo.yml").write_text(
        "default:\n  n_steps: 64\n  learning_rate: lin_1e-3\n  policy_kwargs: {net_arch: [8], activation_fn: relu}\n"
        "my/Env-v0:\n  n_steps: 32\n")
    hp = load_hyperparams("ppo", "my/Env-v0", directory=tmp_path)
    assert hp.algo_kwargs["n_steps"] == 32 and hp.algo_kwargs["policy_kwargs"]["activation_fn"] is nn.ReLU
    assert hp.algo_kwargs["learning_rate"](1.0) == pytest.approx(1e-3)
    other = load_hyperparams("ppo", "other/Env-v0", {"n_steps": 16}, directory=tmp_path)
    assert other.algo_kwargs["n_steps"] == 16


@pytest.mark.parametrize("text, match", [
    ("default:\n  not_a_kwarg: 1\n", "not accepted"),
    ("default:\n  policy_kwargs: \"dict(net_arch=[64])\"\n", "mapping"),
    ("default:\n  policy_kwargs: {activation_fn: swish}\n", "activation_fn"),
    ("default:\n  vec_env: threads\n", "vec_env"),
    ("other/Env-v0: {}\n", "default"),
])
def test_bad_entries_raise(tmp_path: Path, text: str, match: str) -> None:
    (tmp_path / "ppo.yml").write_text(text)
    with pytest.raises(ValueError, match=match):
        load_hyperparams("ppo", "my/Env-v0", directory=tmp_path)


def test_td3_action_noise_built_for_the_action_size() -> None:
    kwargs = constructor_kwargs(load_hyperparams("td3", ENV_ID), action_dim=3)
    assert isinstance(kwargs["action_noise"], NormalActionNoise) and kwargs["action_noise"]().shape == (3,)
