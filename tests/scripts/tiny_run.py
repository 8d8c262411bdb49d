"""Shared by the train.py and compare.py tests: the train command (:mod:`bboxtune.agents.commands.train`) as a fixture, and one
tiny trained run per test module."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest
import torch

from bboxtune.agents.commands import train as train_command

REPO = Path(__file__).resolve().parents[2]
torch.set_num_threads(1)  # tiny MLPs: more intra-op threads only contend for the cores

# A run of a few dozen one-step episodes on 100-frame tracks: seconds, not minutes.
TINY = ["--timesteps", "64", "--n-envs", "2", "--hyperparams", "n_steps:16", "batch_size:32", "vec_env:dummy",
        "--env-kwargs", "track_length:100", "--eval-freq", "32", "--eval-episodes", "4", "--checkpoint-freq", "32"]


@pytest.fixture(scope="module")
def train() -> ModuleType:
    """:mod:`bboxtune.agents.commands.train` (``train.run(argv)`` returns the run directory)."""
    return train_command


@pytest.fixture(scope="module")
def tiny_run(train: ModuleType, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train.run([*TINY, "--out", str(tmp_path_factory.mktemp("runs") / "tiny")])
