"""scripts/sweep.py (agents/training/sweep.py): the grid, sweep.json and trial.csv read back as untrusted input, the
aggregate, and a two-trial smoke sweep on a local Ray resumed without unpickling Ray's state."""

from __future__ import annotations

import csv
import json
import pickle
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from bboxtune.agents.commands import compare
from bboxtune.agents.commands import sweep as sweep_command
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.sweep import (
    SweepSpec,
    aggregate,
    read_spec,
    read_trial,
    resume_state,
    trial_commands,
    write_csv,
    write_spec,
)

from .cli_misuse import check_misuse, misuse


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


def test_swept_values_read_as_train_py_reads_them() -> None:
    p = sweep_command.build_parser()
    argv = ["--out", "x", "--hyperparams", "learning_rate:3e-4,lin_1e-3", "normalize_advantage:true,false", "n_steps:16",
            "policy_kwargs:{net_arch: [8, 8]}"]
    spec = sweep_command.spec_of(p, p.parse_args(argv), argv)
    assert spec.grid == {"learning_rate": [3e-4, "lin_1e-3"], "normalize_advantage": [True, False], "n_steps": [16],
                         "policy_kwargs": [{"net_arch": [8, 8]}]}
    train, _ = trial_commands(spec, spec.trials()[0], Path("t"))
    assert train[train.index("--hyperparams") + 1:][:2] == ["learning_rate:0.0003", "n_steps:16"]


def test_the_smoke_flags_are_valid_flags_of_train_and_compare(tmp_path: Path) -> None:
    spec = sweep_command.SMOKE
    sweep_command.check_trials(spec, spec.trials(), tmp_path / "sweep")  # train.py's checks: raises if refused
    compare_argv = trial_commands(spec, spec.trials()[0], tmp_path)[1][2:]
    compare_argv[compare_argv.index("--model") + 1] = str(tmp_path)  # compare's parser wants an existing folder
    assert compare.build_parser().parse_args(compare_argv).split == "val"
    assert not any(tmp_path.iterdir())


def test_sweep_json_round_trips_and_is_checked_field_by_field(tmp_path: Path) -> None:
    spec = SweepSpec(backends=("ufir_cmn", "kf_cmn"), grid={"learning_rate": [3e-4, "lin_1e-3"]}, timesteps=64)
    path = tmp_path / "sweep.json"
    write_spec(spec, path)
    assert read_spec(path) == spec
    good = json.loads(path.read_text())
    for change, why in ((lambda d: d["spec"].update(seeds=[0, "1"]), "spec.seeds"),
                        (lambda d: d["spec"].update(algos=[]), "must not be empty"),
                        (lambda d: d["spec"].update(timesteps=True), "spec.timesteps"),
                        (lambda d: d["spec"].update(grid={"learning_rate": []}), "spec.grid"),
                        (lambda d: d["spec"].pop("train_args"), "exactly the keys"),
                        (lambda d: d.update(extra=1), "exactly the keys")):
        doc = json.loads(json.dumps(good))
        change(doc)
        path.write_text(json.dumps(doc))
        with pytest.raises(RunError, match=why) as info:
            read_spec(path)
        assert str(path) in str(info.value)
    path.write_text(json.dumps(good).replace("64", "NaN"))
    with pytest.raises(RunError, match="NaN"):
        read_spec(path)


def test_a_resume_keeps_checked_trial_results_only(tmp_path: Path) -> None:
    spec = SweepSpec(seeds=(0, 1))
    first, second = spec.trials()
    write_spec(spec, tmp_path / "sweep.json")
    row = {"name": first["name"], "algo": "ppo", "backend": "ufir_cmn", "source": "sim", "seed": 0, "hyperparams": "{}",
           "val_log_ratio": 0.2, "val_gap_closed": "nan", "val_win_rate": 0.9}
    (tmp_path / "trials" / first["name"]).mkdir(parents=True)
    write_csv(tmp_path / "trials" / first["name"] / "trial.csv", [row])
    assert resume_state(spec, tmp_path) == {first["name"]}
    with pytest.raises(RunError, match="another sweep's settings"):
        resume_state(SweepSpec(seeds=(0, 1, 2)), tmp_path)
    (tmp_path / "trials" / second["name"]).mkdir()
    for bad, why in (({**row, "seed": 0}, "another trial"), ({**row, "seed": 1, "val_win_rate": "x"}, "must be numbers")):
        write_csv(tmp_path / "trials" / second["name"] / "trial.csv", [{**bad, "name": second["name"]}])
        with pytest.raises(RunError, match=why):
            resume_state(spec, tmp_path)
    (tmp_path / "trials" / second["name"] / "trial.csv").write_text("name,algo\nx,ppo\n")
    with pytest.raises(RunError, match="expected a header"):
        read_trial(tmp_path / "trials" / second["name"] / "trial.csv")


def test_a_resume_of_a_tampered_sweep_is_refused_before_ray(misuse_paths, capsys) -> None:
    folder = misuse_paths.root / "folder" / "sweep"
    folder.mkdir()
    (folder / "sweep.json").write_text('{"spec": {"algos": "ppo"}}\n')
    line = check_misuse(sweep_command.main, misuse("--out", "{dir}/sweep", "--resume", "--smoke", mentions="sweep.json"),
                        misuse_paths, capsys)
    assert "not a sweep's settings" in line


class _Planted:
    """A pickle that, when loaded, writes a marker file (what a crafted tuner.pkl could do, with os.system) and
    then gives what ``original`` (a pickle's bytes) holds."""

    def __init__(self, marker: Path, original: bytes) -> None:
        self.marker, self.original = marker, original

    def __reduce__(self):
        return (_mark_and_load, (str(self.marker), self.original))


def _mark_and_load(marker: str, original: bytes) -> object:
    Path(marker).write_text("unpickled")
    return pickle.loads(original)


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
    kept = out / "trials" / "ppo_ufir_cmn_sim_s0" / "trial.csv"
    stamp = kept.stat().st_mtime_ns
    marker, state = tmp_path / "unpickled.txt", out / "ray" / "sweep" / "tuner.pkl"
    state.write_bytes(pickle.dumps(_Planted(marker, state.read_bytes())))  # a crafted sweep folder
    rerun = out / "trials" / "ppo_ufir_cmn_sim_s1" / "trial.csv"
    rerun.unlink()  # an unfinished trial: run again (its run and comparison are there: only trial.csv is written)
    sweep_command.run(["--out", str(out), "--smoke", "--resume", "--cpus", "2"])
    assert not marker.exists() and kept.stat().st_mtime_ns == stamp  # no pickle read; the finished trial kept
    assert read_trial(rerun)["seed"] == "1" and read_spec(out / "sweep.json") == sweep_command.SMOKE
    state.write_bytes(pickle.dumps(_Planted(marker, state.read_bytes())))
    rerun.unlink()
    sweep_command.run(["--out", str(out), "--smoke", "--resume", "--trust-pickle", "--cpus", "2"])
    assert marker.read_text() == "unpickled"  # Ray Tune's own restore: what --trust-pickle vouches for
