"""Each SB3 algorithm trains a few hundred steps on FilterTune-v0 with its YAML hyperparameters."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecNormalize

from bboxtune.agents.training.algos import ALGOS, algo_class
from bboxtune.agents.training.hyperparams import constructor_kwargs, load_hyperparams
from bboxtune.agents.training.runs import make_vec

from ..conftest import ENV_ID, SHORT

SMALL = {"ppo": {"n_steps": 32, "batch_size": 64}, "a2c": {"n_steps": 8}, "sac": {"learning_starts": 64},
         "td3": {"learning_starts": 64}, "ppo_lstm": {"n_steps": 32, "batch_size": 64}}


@pytest.mark.parametrize("algo", sorted(ALGOS))
def test_algo_trains_and_acts_in_range(algo: str) -> None:
    hp = load_hyperparams(algo, ENV_ID, {**SMALL[algo], "n_envs": 2})
    venv = VecNormalize(make_vec(ENV_ID, {"backend": "ufir_cmn", **SHORT}, split="train", n_envs=2, seed=0), **hp.normalize)
    model = algo_class(algo)(hp.policy, venv, seed=0, device="cpu", **constructor_kwargs(hp, 2))
    model.learn(total_timesteps=200)
    assert model.num_timesteps >= 200
    actions, _ = model.predict(venv.reset(), deterministic=True)
    assert actions.shape == (2, 2) and np.all(np.abs(actions) <= 1.0)


@pytest.mark.slow
def test_subproc_and_dummy_vec_envs_train_identically() -> None:
    hp = load_hyperparams("ppo", ENV_ID, {**SMALL["ppo"], "n_envs": 2})
    params = []
    for vec_env in ("dummy", "subproc"):
        venv = VecNormalize(make_vec(ENV_ID, {"backend": "ufir_cmn", **SHORT}, split="train", n_envs=2, seed=0,
                                     vec_env=vec_env), **hp.normalize)
        model = algo_class("ppo")(hp.policy, venv, seed=0, device="cpu", **constructor_kwargs(hp, 2))
        model.learn(total_timesteps=128)
        params.append([p.detach().clone() for p in model.policy.parameters()])
        venv.close()
    assert all(np.array_equal(a.numpy(), b.numpy()) for a, b in zip(*params, strict=False))
