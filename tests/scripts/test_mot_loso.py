"""scripts/mot_loso.py: leave-one-sequence-out tuners on MOT15 (bboxtune.agents.commands.mot_loso) and its refusals."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from bboxtune.agents.commands import mot_eval, mot_loso
from bboxtune.agents.evaluation.mot_eval import Method
from bboxtune.envs.episodes.episode import Episode

MOT_ROOT = os.environ.get("MOT_ROOT")
needs_mot = pytest.mark.skipif(not MOT_ROOT, reason="MOT_ROOT is unset: the LOSO table needs the MOT15 data "
                                                   "(CI: MOT_ROOT=../shared/data/mot15)")
FOLD = ["--mot-root", str(MOT_ROOT), "--folds", "KITTI-13", "--backend", "bytetrack_kf", "--seeds", "0"]


def rows_of(path: Path) -> list[dict[str, str]]:
    with open(path) as f:
        return list(csv.DictReader(f))


@needs_mot
def test_one_fold_end_to_end_then_reused(tmp_path: Path) -> None:
    runs, out = tmp_path / "runs", tmp_path / "out"
    assert mot_loso.main([*FOLD, "--timesteps", "64", "--runs", str(runs), "--out", str(out)]) == 0
    run_dir = runs / "KITTI-13" / "bytetrack_kf_s0"
    config = yaml.safe_load((run_dir / "config.yml").read_text())
    assert config["env_kwargs"]["mot_holdout"] == "KITTI-13" and config["env_kwargs"]["otb_speedup_max"] == 3
    table = rows_of(out / "per_identity.csv")
    methods = {"raw", "bytetrack_kf", "sort_kf", "rule_kf", "rule_kf_cmn", "rule_ufir_cmn", "bytetrack_kf +gap",
               "bytetrack_kf s0", "bytetrack_kf s0 +gap"}
    assert {r["method"] for r in table} == methods and len(table) == 15 * len(methods)
    assert {r["identity"].split("/")[0] for r in table} == {"KITTI-13"}
    # the baselines score as in mot_eval.py's fixed test split (KITTI-13 is its test sequence)
    fixed = tmp_path / "fixed"
    assert mot_eval.main(["--mot-root", str(MOT_ROOT), "--split", "test", "--out", str(fixed)]) == 0
    fixed_rows = {(r["method"], r["identity"]): r for r in rows_of(fixed / "per_identity.csv")}
    for r in table:
        if r["method"] in ("raw", "bytetrack_kf", "sort_kf", "rule_kf"):
            assert r == fixed_rows[(r["method"], r["identity"])]
    folds = rows_of(out / "folds.csv")
    assert {r["method"]: r["gap_policy"] != "" for r in folds} == {m: m.endswith("+gap") for m in methods}
    assert all(r["identities"] == "15" for r in folds)
    summary = (out / "summary.md").read_text()
    assert "15 identities of KITTI-13" in summary and "| bytetrack_kf s0 +gap | " in summary
    assert (out / "command.txt").read_text().startswith("python scripts/mot_loso.py --mot-root")
    # a second table over the same runs reuses them: no training, the same scores
    model_time = (run_dir / "model.zip").stat().st_mtime_ns
    assert mot_loso.main([*FOLD, "--timesteps", "64", "--runs", str(runs), "--out", str(tmp_path / "again")]) == 0
    assert (run_dir / "model.zip").stat().st_mtime_ns == model_time
    assert (tmp_path / "again" / "per_identity.csv").read_text() == (out / "per_identity.csv").read_text()


@needs_mot
def test_refuses_a_run_folder_of_other_settings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "runs"
    assert mot_loso.main([*FOLD, "--timesteps", "64", "--runs", str(runs), "--out", str(tmp_path / "a")]) == 0
    capsys.readouterr()
    assert mot_loso.main([*FOLD, "--timesteps", "128", "--runs", str(runs), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "bytetrack_kf_s0: holds a run of other settings" in err and err.count("\n") == 1
    assert not (tmp_path / "b").exists()
    (runs / "KITTI-13" / "bytetrack_kf_s0" / "config.yml").write_text("seed: [unclosed\n")  # a damaged finished run
    assert mot_loso.main([*FOLD, "--timesteps", "64", "--runs", str(runs), "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "bytetrack_kf_s0/config.yml" in err and err.count("\n") == 1
    assert not (tmp_path / "c").exists()


@needs_mot
def test_refuses_an_unfinished_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run_dir = tmp_path / "runs" / "KITTI-13" / "bytetrack_kf_s0"
    run_dir.mkdir(parents=True)
    (run_dir / "config.yml").write_text("x")  # an interrupted run
    assert mot_loso.main([*FOLD, "--timesteps", "64", "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {run_dir}: holds an unfinished run (no model.zip); remove it or give another --runs folder\n"
    assert (run_dir / "config.yml").read_text() == "x" and not (tmp_path / "o").exists()


@needs_mot
def test_refuses_an_unknown_fold_before_training(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--mot-root", str(MOT_ROOT), "--folds", "KITTI-13", "KITTI-14", "--runs", str(tmp_path / "runs"),
            "--out", str(tmp_path / "out")]
    assert mot_loso.main(argv) == 2
    assert "mot_holdout='KITTI-14' is not a sequence of the MOT data" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists() and not (tmp_path / "out").exists()


@pytest.mark.parametrize(("flag", "values"), [("--folds", ["KITTI-13", "KITTI-13"]), ("--seeds", ["0", "1", "0"]),
                                              ("--backend", ["kf_cmn", "kf_cmn"])])
def test_refuses_a_repeated_value(tmp_path: Path, capsys: pytest.CaptureFixture[str], flag: str, values: list[str]) -> None:
    args = [flag, *values] if flag != "--backend" else [a for v in values for a in (flag, v)]
    with pytest.raises(SystemExit) as stop:
        mot_loso.main([*args, "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and f"argument {flag}: " in err and "repeats a value" in err and err.count("\n") == 1
    assert not (tmp_path / "runs").exists() and not (tmp_path / "out").exists()


def test_refuses_a_used_output_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "folds.csv").write_text("mine")
    assert mot_loso.main(["--runs", str(tmp_path / "runs"), "--out", str(tmp_path)]) == 2
    assert "already holds folds.csv" in capsys.readouterr().err
    assert (tmp_path / "folds.csv").read_text() == "mine"


def test_gap_policy_selection_takes_the_best_and_the_first_of_ties() -> None:
    episode = Episode(truth=np.tile([10.0, 10.0, 4.0, 4.0], (3, 1)), y=np.array([[10, 10, 4, 4], [np.nan] * 4, [10, 10, 4, 4]]),
                      tau=0.1, nominal=None, meta={})  # type: ignore[arg-type]

    def shifted(dx: float) -> Method:
        return lambda episodes: [ep.truth + [dx, 0, 0, 0] for ep in episodes]

    assert mot_loso.best_gap_policy({(1, 1): shifted(2), (0.5, 0): shifted(0), (0, 0): shifted(1)}, [episode]) == (0.5, 0)
    assert mot_loso.best_gap_policy({(1, 1): shifted(1), (0.5, 0): shifted(1)}, [episode]) == (1, 1)
    assert mot_loso.best_gap_policy({(1, 1): shifted(1), (0.5, 0): shifted(-1)}, [episode]) == (1, 1)
