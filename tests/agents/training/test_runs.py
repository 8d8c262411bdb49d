"""Run directories: claiming an output folder (also when two processes race for it), the run lock, config.yml
checks, and choosing the newest complete checkpoint."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import yaml

from bboxtune.agents.training.checkpoints import CHECKPOINTS, LATEST, checkpoint_name, newest_complete
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import LOCK, RESUME_KEYS, RunLock, claim_run_dir, load_config

CONFIG = {"algo": "ppo", "env_id": "bboxtune/FilterTune-v0", "env_kwargs": {"backend": "kf"}, "hyperparams": {},
          "seed": 0, "total_timesteps": 64, "eval_freq": 32, "eval_episodes": 4, "checkpoint_freq": 32,
          "tensorboard": False}


def test_claim_is_exclusive_and_refuses_a_non_empty_folder(tmp_path: Path) -> None:
    out = tmp_path / "a" / "run"
    first = claim_run_dir(out)  # creates the parents too
    with pytest.raises(RunError, match=rf"{out} is in use by another train.py \(pid {os.getpid()}\)"):
        claim_run_dir(out)  # a racer that also found the folder empty
    (out / "config.yml").write_text("algo: ppo\n")
    first.release()
    with pytest.raises(RunError, match="exists and is not empty"):
        claim_run_dir(out)
    (out / "config.yml").unlink()
    claim_run_dir(out).release()  # a lone lock file (a run killed before writing anything) counts as empty
    assert [p.name for p in out.iterdir()] == [LOCK]
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunError, match="exists and is not a folder"):
        claim_run_dir(tmp_path / "file")


def test_lock_is_released_with_the_object_and_records_the_pid(tmp_path: Path) -> None:
    with RunLock(tmp_path).acquire():
        assert (tmp_path / LOCK).read_text().strip() == str(os.getpid())
        with pytest.raises(RunError, match="in use"):
            RunLock(tmp_path).acquire()
    RunLock(tmp_path).acquire().release()


@pytest.mark.parametrize(("text", "message"), [
    ("- a\n- b\n", "expected a mapping of settings, got list"),
    ("algo: ppo\nenv_id: [a\n", r"config\.yml:3:1: invalid YAML"),
    (yaml.safe_dump({**CONFIG, "algo": "dqn"}), "algo='dqn'; allowed"),
    (yaml.safe_dump({k: v for k, v in CONFIG.items() if k != "env_kwargs"}), "env_kwargs=None; expected a dict"),
    (yaml.safe_dump({**CONFIG, "seed": True}), "seed=True; expected a int"),
    (yaml.safe_dump({**CONFIG, "total_timesteps": 0}), "total_timesteps=0; allowed: integers >= 1"),
])
def test_config_is_checked_naming_the_file(text: str, message: str, tmp_path: Path) -> None:
    (tmp_path / "config.yml").write_text(text)
    with pytest.raises(RunError, match=message) as info:
        load_config(tmp_path, RESUME_KEYS)
    assert str(tmp_path / "config.yml") in str(info.value)


def test_config_of_a_folder_that_is_not_a_run(tmp_path: Path) -> None:
    with pytest.raises(RunError, match="not a train.py run directory: no config.yml"):
        load_config(tmp_path)
    with pytest.raises(RunError, match="does not exist"):
        load_config(tmp_path / "nope")


def make_checkpoint(run: Path, steps: int, state: dict | None = None) -> Path:
    folder = run / CHECKPOINTS / checkpoint_name(steps)
    folder.mkdir(parents=True)
    (folder / "state.json").write_text(json.dumps(state if state is not None else {"num_timesteps": steps}))
    return folder


def test_newest_complete_checkpoint_falls_back_and_reports(tmp_path: Path) -> None:
    for steps in (32, 64, 96):
        make_checkpoint(tmp_path, steps)
    make_checkpoint(tmp_path, 128, {"num_timesteps": 7})  # state of another folder
    (tmp_path / CHECKPOINTS / "ckpt_000000000160.tmp").mkdir()  # an unfinished save: never a candidate
    (tmp_path / CHECKPOINTS / LATEST).write_text("../../etc")

    def check(folder: Path) -> None:
        if folder.name == checkpoint_name(96):
            raise RunError(f"{folder / 'model.zip'}: not a readable zip archive")

    log: list[str] = []
    found = newest_complete(tmp_path, check, log.append)
    assert found.folder.name == checkpoint_name(64) and found.num_timesteps == 64
    assert any("latest: '../../etc' is not a checkpoint name" in line for line in log)
    assert any("ckpt_000000000128" in line and "num_timesteps=7 does not match" in line for line in log)
    assert any("ckpt_000000000096" in line and "model.zip: not a readable zip archive" in line for line in log)


def test_no_checkpoint_and_no_complete_checkpoint(tmp_path: Path) -> None:
    assert newest_complete(tmp_path, lambda folder: None, print) is None  # stopped before its first checkpoint
    make_checkpoint(tmp_path, 32, {"num_timesteps": 32, "episode_timesteps": [1], "episode_rewards": []})
    with pytest.raises(RunError, match="no complete checkpoint .*episode_timesteps and episode_rewards differ"):
        newest_complete(tmp_path, lambda folder: None, print)
