"""Shared by the train.py and compare.py tests: the scripts imported as modules, and one tiny trained run per module."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest
import torch

REPO = Path(__file__).resolve().parents[2]
torch.set_num_threads(1)  # tiny MLPs: more intra-op threads only contend for the cores

# A run of a few dozen one-step episodes on 100-frame tracks: seconds, not minutes.
TINY = ["--timesteps", "64", "--n-envs", "2", "--hyperparams", "n_steps:16", "batch_size:32", "vec_env:dummy",
        "--env-kwargs", "track_length:100", "--eval-freq", "32", "--eval-episodes", "4", "--checkpoint-freq", "32"]


def load_script(name: str) -> ModuleType:
    """``scripts/<name>.py`` as a module, imported as ``python scripts/<name>.py`` would run it: with scripts/ on
    ``sys.path`` (its sibling modules, e.g. ``video_common``, import by name); the packages come from the install."""
    if str(REPO / "scripts") not in sys.path:
        sys.path.append(str(REPO / "scripts"))
    spec = importlib.util.spec_from_file_location(f"script_{name}", REPO / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def train() -> ModuleType:
    return load_script("train")


@pytest.fixture(scope="module")
def tiny_run(train: ModuleType, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train.main([*TINY, "--out", str(tmp_path_factory.mktemp("runs") / "tiny")])
