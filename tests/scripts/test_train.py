"""scripts/train.py end to end with tiny runs: run directory, resume after a kill, determinism."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import torch
import yaml

from agents.runs import CHECKPOINTS, LATEST, latest_checkpoint
from stable_baselines3 import PPO

from .tiny_run import TINY, tiny_run, train  # noqa: F401  (fixtures)

RUN_FILES = ("model.zip", "vecnormalize.pkl", "best_model.zip", "best_vecnormalize.pkl", "config.yml", "command.txt",
             "evaluations.npz", "eval_curve.csv", "train_log.csv", "learning_curve.png")


def test_help_documents_the_flags(train: ModuleType, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        train.parse_args(["--help"])
    text = capsys.readouterr().out
    for flag in ("--algo", "--env", "--backend", "--source", "--reward", "--timesteps", "--seed", "--n-envs", "--out",
                 "--resume", "--tensorboard"):
        assert flag in text


def test_run_directory(tiny_run: Path) -> None:
    for name in RUN_FILES:
        assert (tiny_run / name).is_file(), name
    cfg = yaml.safe_load((tiny_run / "config.yml").read_text())
    assert cfg["algo"] == "ppo" and cfg["env_kwargs"]["backend"] == "ufir_cmn" and cfg["seed"] == 0
    assert cfg["env_kwargs"]["track_length"] == 100 and cfg["hyperparams"]["n_steps"] == 16
    assert "--timesteps 64" in (tiny_run / "command.txt").read_text()
    assert PPO.load(tiny_run / "model.zip").num_timesteps == 64
    assert latest_checkpoint(tiny_run).name == "ckpt_000000000064"
    lines = (tiny_run / "train_log.csv").read_text().splitlines()
    assert lines[0] == "timestep,reward" and len(lines) == 1 + 64


def test_refuses_to_overwrite_a_run(train: ModuleType, tiny_run: Path) -> None:
    with pytest.raises(SystemExit, match="not empty"):
        train.main([*TINY, "--out", str(tiny_run)])


def test_resume_after_a_kill_loses_nothing(train: ModuleType, tiny_run: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "killed"
    shutil.copytree(tiny_run, run)
    # as if killed after the first checkpoint: later files gone, `latest` still on the first one
    for name in ("model.zip", "vecnormalize.pkl", "train_log.csv"):
        (run / name).unlink()
    shutil.rmtree(run / CHECKPOINTS / "ckpt_000000000064")
    (run / CHECKPOINTS / LATEST).write_text("ckpt_000000000032")
    train.main(["--resume", str(run)])
    assert "seed: 0" in capsys.readouterr().out
    assert PPO.load(run / "model.zip").num_timesteps == 64
    steps = [int(line.split(",")[0]) for line in (run / "train_log.csv").read_text().splitlines()[1:]]
    assert len(steps) == 64 and steps == sorted(steps)
    evals = np.load(run / "evaluations.npz")["timesteps"]
    assert list(evals) == sorted(set(evals)) and evals[-1] == 64
    assert (run / "command.txt").read_text().count("\n") == 2
    train.main(["--resume", str(run), "--timesteps", "96"])  # and a longer total continues further
    assert PPO.load(run / "model.zip").num_timesteps == 96


def test_same_seed_same_result(train: ModuleType, tiny_run: Path, tmp_path: Path) -> None:
    again = train.main([*TINY, "--out", str(tmp_path / "again")])
    a, b = PPO.load(tiny_run / "model.zip"), PPO.load(again / "model.zip")
    for (name, p), (_, q) in zip(a.policy.state_dict().items(), b.policy.state_dict().items()):
        assert torch.equal(p, q), name
    assert (tiny_run / "train_log.csv").read_text() == (again / "train_log.csv").read_text()


def test_tensorboard_without_the_package_fails_clearly(train: ModuleType, tmp_path: Path) -> None:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        with pytest.raises(SystemExit, match="tensorboard"):
            train.main([*TINY, "--out", str(tmp_path / "tb"), "--tensorboard"])
    else:
        pytest.skip(reason="tensorboard is installed here, so the missing-package error cannot occur")
