"""scripts/sweep.py (agents/training/sweep.py): the grid, the aggregate, and a two-trial smoke sweep on a local Ray."""

from __future__ import annotations

import csv
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from bboxtune.agents.commands import sweep as sweep_command
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.sweep import SweepSpec, aggregate, trial_commands, write_csv


def test_the_grid_is_the_product_of_its_axes() -> None:
    spec = SweepSpec(backends=("ufir_cmn", "kf_cmn"), seeds=(0, 1), grid={"learning_rate": [3e-4, 1e-3]})
    trials = spec.trials()
    assert len(trials) == 2 * 2 * 2 and len({t["name"] for t in trials}) == 8
    assert {"name": "ppo_kf_cmn_sim_learning_rate-0.001_s1", "algo": "ppo", "backend": "kf_cmn", "source": "sim",
            "hyperparams": {"learning_rate": 1e-3}, "seed": 1} in trials


def test_a_trial_trains_then_scores_on_val_and_resumes_a_checkpointed_run(tmp_path: Path) -> None:
    spec = SweepSpec(timesteps=512, grid={"n_steps": [16]})
    trial = spec.trials()[0]
    train, compare = trial_commands(spec, trial, tmp_path)
    assert train[1].endswith("scripts/train.py") and ["--timesteps", "512"] == train[train.index("--timesteps"):][:2]
    assert "n_steps:16" in train and compare[compare.index("--split") + 1] == "val"
    (tmp_path / "run" / "checkpoints").mkdir(parents=True)
    (tmp_path / "run" / "checkpoints" / "latest").write_text("ckpt_000000000256\n")
    assert trial_commands(spec, trial, tmp_path)[0][2:] == ["--resume", str(tmp_path / "run")]


def test_the_aggregate_groups_seeds_of_one_setting(tmp_path: Path) -> None:
    for seed, ratio in ((0, 0.2), (1, 0.4), (2, 0.1)):
        row = {"name": f"t{seed}", "algo": "ppo", "backend": "ufir_cmn", "source": "sim", "seed": seed,
               "hyperparams": '{"learning_rate": 0.001}' if seed < 2 else "{}", "val_log_ratio": ratio,
               "val_gap_closed": ratio * 2, "val_win_rate": 0.9}
        folder = tmp_path / "trials" / f"t{seed}"
        folder.mkdir(parents=True)
        write_csv(folder / "trial.csv", [row])
    table = aggregate(tmp_path)
    assert [(r["hyperparams"], r["seeds"]) for r in table] == [('{"learning_rate": 0.001}', "0 1"), ("{}", "2")]
    assert table[0]["val_log_ratio_mean"] == pytest.approx(0.3) and table[0]["val_log_ratio_min"] == pytest.approx(0.2)
    with open(tmp_path / "aggregate.csv", newline="") as fh:
        assert list(csv.DictReader(fh))[0]["hyperparams"] == '{"learning_rate": 0.001}'  # the comma-free JSON cell
    assert "| ppo | ufir_cmn | sim |" in (tmp_path / "aggregate.md").read_text()
    with pytest.raises(RunError, match="no finished trial"):
        aggregate(tmp_path / "empty")


@pytest.fixture
def ray_temp(monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """Ray's session folder, removed afterwards. Not under pytest's temp folder: Ray's socket paths there would pass
    the 107-byte limit of AF_UNIX."""
    folder = Path(tempfile.mkdtemp(prefix="bbt-ray-", dir="/tmp"))
    monkeypatch.setenv("RAY_TMPDIR", str(folder))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def test_smoke_sweep_runs_two_trials_and_aggregates_them(tmp_path: Path, capsys, ray_temp: Path) -> None:
    out = sweep_command.run(["--out", str(tmp_path / "sweep"), "--smoke", "--cpus", "2"])
    for seed in (0, 1):
        trial = out / "trials" / f"ppo_ufir_cmn_sim_s{seed}"
        assert (trial / "run" / "model.zip").is_file() and (trial / "compare" / "summary.md").is_file()
        with open(trial / "trial.csv", newline="") as fh:
            assert int(next(csv.DictReader(fh))["seed"]) == seed
    with open(out / "aggregate.csv", newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["seeds"] == "0 1" and float(row["val_win_rate_min"]) >= 0
    assert "1 setting(s)" in capsys.readouterr().out
    again = sweep_command.run(["--out", str(out), "--smoke", "--resume", "--cpus", "2"])  # nothing left to run
    assert (again / "trials" / "ppo_ufir_cmn_sim_s0" / "trial.csv").stat().st_mtime == \
        (out / "trials" / "ppo_ufir_cmn_sim_s0" / "trial.csv").stat().st_mtime
