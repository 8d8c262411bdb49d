"""Fixtures of the agents tests: short simulated tracks so that every test runs in seconds."""

from __future__ import annotations

import gymnasium as gym
import pytest
import torch

from bboxtune import envs  # noqa: F401

torch.set_num_threads(1)  # tiny MLPs: more intra-op threads only contend for the cores

ENV_ID = "bboxtune/FilterTune-v0"
SHORT = {"track_length": 100}


@pytest.fixture(params=["ufir_cmn", "kf_cmn"])
def env(request: pytest.FixtureRequest) -> gym.Env:
    """A short-track FilterTune-v0 env of each CMN back end."""
    return gym.make(ENV_ID, backend=request.param, **SHORT)
