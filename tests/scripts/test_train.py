"""scripts/train.py end to end with tiny runs: run directory, resume after a kill (and from corrupt checkpoints),
what --timesteps means on resume, the run lock, determinism."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import torch
import yaml

from bboxtune.agents.training.checkpoints import CHECKPOINTS, LATEST
from bboxtune.agents.training.runs import LOCK, RunLock, SB3Policy

from .tiny_run import REPO, TINY

RUN_FILES = ("model.zip", "vecnormalize.json", "best_model.zip", "best_vecnormalize.json", "config.yml", "command.txt",
             "evaluations.npz", "eval_curve.csv", "train_log.csv", "learning_curve.png", LOCK)


def steps(run: Path, which: str = "final") -> int:
    return SB3Policy.load(run, which).model.num_timesteps


def error_line(run, capsys: pytest.CaptureFixture) -> str:
    """The one stderr line of a train.main call that must exit with status 2."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        run()
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.splitlines()) == 1, err
    return err


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
    assert steps(tiny_run) == 64
    assert (tiny_run / CHECKPOINTS / LATEST).read_text().strip() == "ckpt_000000000064"
    assert sorted(p.name for p in (tiny_run / CHECKPOINTS / "ckpt_000000000064").iterdir()) == [
        "model.zip", "state.json", "vecnormalize.json"]
    assert not list(tiny_run.rglob("*.pkl")) and not list(tiny_run.rglob("*tmp*"))  # no pickles, no leftovers
    lines = (tiny_run / "train_log.csv").read_text().splitlines()
    assert lines[0] == "timestep,reward" and len(lines) == 1 + 64


def test_refuses_to_overwrite_a_run(train: ModuleType, tiny_run: Path, capsys: pytest.CaptureFixture) -> None:
    before = {p: p.stat().st_mtime_ns for p in tiny_run.rglob("*")}
    assert "exists and is not empty" in error_line(lambda: train.run([*TINY, "--out", str(tiny_run)]), capsys)
    assert {p: p.stat().st_mtime_ns for p in tiny_run.rglob("*")} == before


def test_resume_after_a_kill_loses_nothing(train: ModuleType, tiny_run: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "killed"
    shutil.copytree(tiny_run, run)
    # as if killed after the first checkpoint: later files gone, `latest` still on the first one
    for name in ("model.zip", "vecnormalize.json", "train_log.csv"):
        (run / name).unlink()
    shutil.rmtree(run / CHECKPOINTS / "ckpt_000000000064")
    (run / CHECKPOINTS / LATEST).write_text("ckpt_000000000032")
    config = (run / "config.yml").read_bytes()
    train.run(["--resume", str(run)])
    assert "seed: 0" in capsys.readouterr().out
    assert steps(run) == 64
    steps_logged = [int(line.split(",")[0]) for line in (run / "train_log.csv").read_text().splitlines()[1:]]
    assert len(steps_logged) == 64 and steps_logged == sorted(steps_logged)
    evals = np.load(run / "evaluations.npz")["timesteps"]
    assert list(evals) == sorted(set(evals)) and evals[-1] == 64
    assert (run / "command.txt").read_text().count("\n") == 2
    train.run(["--resume", str(run), "--timesteps", "96"])  # --timesteps is the total: on to 96
    assert steps(run) == 96
    assert json.loads((run / CHECKPOINTS / "ckpt_000000000096" / "state.json").read_text())["total_timesteps"] == 96
    train.run(["--resume", str(run)])  # the target is kept: nothing to do, nothing rewound
    assert "already trained for 96 >= 96" in capsys.readouterr().out and steps(run) == 96
    assert (run / "config.yml").read_bytes() == config  # a resume never rewrites config.yml
    line = error_line(lambda: train.run(["--resume", str(run), "--timesteps", "80"]), capsys)
    assert "--timesteps 80 is below the 96 timesteps" in line
    assert "cannot be given with --resume" in error_line(
        lambda: train.run(["--resume", str(run), "--backend", "kf", "--timesteps", "128"]), capsys)
    assert steps(run) == 96 and (run / "config.yml").read_bytes() == config


@pytest.mark.parametrize(("corrupt", "named"), [
    (lambda ckpt: (ckpt / "model.zip").write_bytes((ckpt / "model.zip").read_bytes()[:4000]), "model.zip: not a readable zip"),
    (lambda ckpt: (ckpt / "state.json").write_text('{"num_timesteps": 64, "episode_'), "state.json:1:"),
    (lambda ckpt: (ckpt / "vecnormalize.json").write_text("{}"), "vecnormalize.json: not a statistics file"),
    (lambda ckpt: (ckpt / "vecnormalize.json").unlink(), "vecnormalize.json is missing"),
])
def test_resume_skips_a_corrupt_checkpoint_naming_the_file(corrupt, named: str, train: ModuleType, tiny_run: Path,
                                                           tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "corrupt"
    shutil.copytree(tiny_run, run)
    corrupt(run / CHECKPOINTS / "ckpt_000000000064")
    (run / CHECKPOINTS / LATEST).write_bytes(b"\x00garbage/../../x")
    train.run(["--resume", str(run)])
    out = capsys.readouterr().out
    assert f"skipping checkpoint ckpt_000000000064: {run / CHECKPOINTS / 'ckpt_000000000064'}" in out and named in out
    assert f"{run / CHECKPOINTS / LATEST}: " in out and f"resuming from {run / CHECKPOINTS / 'ckpt_000000000032'}" in out
    assert steps(run) == 64 and (run / CHECKPOINTS / LATEST).read_text().strip() == "ckpt_000000000064"


def test_resume_with_no_complete_checkpoint_fails_naming_it(train: ModuleType, tiny_run: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "broken"
    shutil.copytree(tiny_run, run)
    for ckpt in (run / CHECKPOINTS).glob("ckpt_*"):
        (ckpt / "model.zip").write_bytes(b"PK\x03\x04 truncated")
    line = error_line(lambda: train.run(["--resume", str(run)]), capsys)
    assert "no complete checkpoint" in line and "model.zip: not a readable zip archive" in line


def test_off_policy_resume_restores_the_replay_buffer(train: ModuleType, tmp_path: Path) -> None:
    run = tmp_path / "sac"
    train.run(["--algo", "sac", "--timesteps", "48", "--hyperparams", "learning_starts:16", "buffer_size:256",
                "batch_size:16", "--env-kwargs", "track_length:100", "--eval-freq", "24", "--eval-episodes", "2",
                "--checkpoint-freq", "24", "--out", str(run)])
    first, last = (run / CHECKPOINTS / f"ckpt_0000000000{n}" for n in (24, 48))
    with np.load(first / "replay_buffer.npz") as early:
        head = early["observations"][:24].copy()
        assert int(early["pos"]) == 24
    shutil.rmtree(last)  # as if killed before the second checkpoint
    train.run(["--resume", str(run)])
    with np.load(last / "replay_buffer.npz") as data:
        assert int(data["pos"]) == 48 and np.array_equal(data["observations"][:24], head)
        assert np.all(np.any(data["observations"][24:48] != 0, axis=-1))
    assert steps(run) == 48 and not list(run.rglob("*.pkl"))


def test_a_run_stopped_before_its_first_checkpoint_resumes_from_zero(train: ModuleType, tiny_run: Path,
                                                                      tmp_path: Path) -> None:
    run = tmp_path / "early"
    shutil.copytree(tiny_run, run)
    shutil.rmtree(run / CHECKPOINTS)
    (run / "model.zip").unlink()
    train.run(["--resume", str(run)])
    assert steps(run) == 64 and (run / CHECKPOINTS / LATEST).read_text().strip() == "ckpt_000000000064"
    a, b = SB3Policy.load(tiny_run).model, SB3Policy.load(run).model  # the same run as an uninterrupted one
    assert all(torch.equal(p, q) for p, q in zip(a.policy.state_dict().values(), b.policy.state_dict().values(), strict=False))


def test_a_running_run_is_locked(train: ModuleType, tiny_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "locked"
    shutil.copytree(tiny_run, run)
    with RunLock(run).acquire():  # as another train.py writing it
        line = error_line(lambda: train.run(["--resume", str(run), "--timesteps", "96"]), capsys)
        assert f"{run} is in use by another train.py (pid {os.getpid()})" in line
    assert steps(run) == 64  # nothing was trained or written
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from bboxtune.agents.training.runs import RunLock; "
                               "RunLock(sys.argv[1]).acquire(); print('locked', flush=True); time.sleep(60)", str(run)],
                              cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(Exception, match=f"in use by another train.py \\(pid {holder.pid}\\)"):
            RunLock(run).acquire()
    finally:
        holder.send_signal(signal.SIGKILL)  # kill -9: the OS drops the lock
        holder.wait(timeout=30)
    train.run(["--resume", str(run), "--timesteps", "96"])
    assert steps(run) == 96


def test_config_errors_stop_before_anything_is_written(tmp_path: Path) -> None:
    """The issue's case: a bad env argument with SubprocVecEnv workers (each raised it: ~200 lines of tracebacks)
    and a half-made run directory. Now one line from the main process, exit 2, no folder."""
    out = tmp_path / "bad"
    done = subprocess.run([sys.executable, str(REPO / "scripts" / "train.py"), *TINY, "--hyperparams", "vec_env:subproc",
                           "--env-kwargs", "track_length:3", "--out", str(out)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    (line,) = done.stderr.splitlines()
    assert line.startswith("train.py: error: ") and "track_length=3" in line
    assert not out.exists()


def test_same_seed_same_result(train: ModuleType, tiny_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    again = train.run([*TINY, "--out", str(tmp_path / "again")])
    # every tiny track has 100 frames and no gap: the run reports the inputs a tuner will hold when applied elsewhere
    assert "held at their training value wherever the tuner is applied): ppo: frac_missing, log_n_frames" in \
        capsys.readouterr().out
    a, b = SB3Policy.load(tiny_run).model, SB3Policy.load(again).model
    for (name, p), (_, q) in zip(a.policy.state_dict().items(), b.policy.state_dict().items(), strict=False):
        assert torch.equal(p, q), name
    assert (tiny_run / "train_log.csv").read_text() == (again / "train_log.csv").read_text()


def test_tensorboard_without_the_package_fails_clearly(train: ModuleType, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture) -> None:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        line = error_line(lambda: train.run([*TINY, "--out", str(tmp_path / "tb"), "--tensorboard"]), capsys)
        assert "tensorboard" in line and not (tmp_path / "tb").exists()
    else:
        pytest.skip(reason="tensorboard is installed here, so the missing-package error cannot occur")


@pytest.mark.parametrize("argv, expected", [
    (["--source", "otb_tracker"], "train"),  # the default: never the held-out trackers
    (["--source", "mix"], "train"),
    (["--source", "mix", "--env-kwargs", "mix_weights=[1, 1, 0]"], None),  # no tracker episodes: nothing to set
    (["--source", "mix", "--env-kwargs", "mix_weights=[1, 0, 0, 1]"], None),  # sim + MOT15: no tracker episodes either
    (["--source", "mix", "--env-kwargs", "mix_weights=[0, 0, 1, 1]"], "train"),
    (["--source", "otb_tracker", "--trackers", "test"], "test"),
    (["--source", "otb_tracker", "--trackers", "SiamFC,STRUCK"], ["SiamFC", "STRUCK"]),
    (["--source", "otb_tracker", "--env-kwargs", "tracker=STRUCK"], None),  # one tracker given: kept as it is
    (["--source", "otb"], None),
])
def test_tracker_set_of_a_new_run(train: ModuleType, argv: list[str], expected) -> None:
    from bboxtune.envs.data.otb import TRACKER_SPLIT

    args = train.parse_args(argv)
    want = list(TRACKER_SPLIT[expected]) if isinstance(expected, str) else expected
    assert args.env_kwargs.get("trackers") == want


@pytest.mark.parametrize("argv, expected", [
    ([], "msd"),  # FilterTune-v0 trains on the msd feature set by default
    (["--features", "base"], "base"),
    (["--env", "bboxtune/FilterRetune-v0"], "base"),
    (["--env", "bboxtune/FilterRetune-v0", "--features", "msd"], "msd"),  # refused later, by the env's own check
])
def test_feature_set_of_a_new_run(train: ModuleType, argv: list[str], expected: str) -> None:
    args = train.parse_args([*argv, "--out", "x"])
    assert args.features == expected and train.new_config(args)["env_kwargs"]["features"] == expected


def test_the_feature_set_is_a_flag_and_the_retune_env_refuses_msd(train: ModuleType, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    err = error_line(lambda: train.main(["--env-kwargs", "features=base", "--out", str(tmp_path / "a")]), capsys)
    assert "--env-kwargs ['features']: use --backend/--source/--reward/--features" in err
    err = error_line(lambda: train.main(["--features", "all", "--out", str(tmp_path / "b")]), capsys)
    assert "--features: invalid choice: 'all'" in err
    err = error_line(lambda: train.main(["--env", "bboxtune/FilterRetune-v0", "--features", "msd", "--timesteps", "8",
                                         "--out", str(tmp_path / "c")]), capsys)
    assert "features='msd' with FilterRetune-v0; allowed: 'base'" in err
    assert not (tmp_path / "c").exists()


def test_a_run_leaves_nothing_in_the_temp_directory(train: ModuleType, tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """SB3's default logger makes an empty ``SB3-<date>`` folder in the temp directory for every learn() call (torch
    may keep its own compile cache there, ``torchinductor_<user>``: torch's, shared by the process)."""
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr("tempfile.tempdir", str(temp))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    train.run([*TINY, "--timesteps", "32", "--out", str(tmp_path / "run")])
    assert [p.name for p in temp.iterdir() if not p.name.startswith("torchinductor_")] == []
