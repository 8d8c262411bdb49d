"""A run directory from someone else cannot run code: pickles planted in model.zip (every serialized entry, also
in the checkpoints) are never unpickled by compare.py, train.py --resume, track_video.py --tuned or
SB3Policy.load; an old run whose statistics are only a (planted) vecnormalize.pkl is refused with one line
asking for --trust-pickle, and with --trust-pickle an honest old run loads and is converted to JSON.

Each plant has a positive control (SB3's own readers run it), so the marker file proves the plant is live.
"""

from __future__ import annotations

import base64
import json
import pickle
import shutil
import zipfile
from pathlib import Path
from types import ModuleType

import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from bboxtune.agents.commands import compare, track_video
from bboxtune.agents.training.run_files import RunError, load_stats
from bboxtune.agents.training.runs import SB3Policy, env_spaces_venv, load_config

COMPARE = ["--episodes", "2", "--train-episodes", "11", "--global-trials", "2", "--oracle-budget", "8", "--bootstrap", "20"]


class Plant:
    """Unpickles to ``open(marker, "w")``: creates the marker file."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def naive(load, *args, **kwargs) -> None:
    """Positive control: SB3's own reader on a planted file (it runs the plant, then may fail on what it got)."""
    try:
        load(*args, **kwargs)
    except Exception:  # noqa: BLE001  (only whether the plant ran matters)
        pass


def plant_models(run: Path, marker: Path) -> int:
    """Every serialized data entry of every model.zip below ``run`` runs the plant when unpickled; returns how
    many entries were planted."""
    payload = base64.b64encode(pickle.dumps(Plant(marker))).decode()
    planted = 0
    for path in run.rglob("*model.zip"):
        with zipfile.ZipFile(path) as archive:
            members = {n: archive.read(n) for n in archive.namelist()}
        data = json.loads(members["data"])
        for value in data.values():
            if isinstance(value, dict) and ":serialized:" in value:
                value[":serialized:"] = payload
                planted += 1
        members["data"] = json.dumps(data).encode()
        with zipfile.ZipFile(path, "w") as archive:
            for name, content in members.items():
                archive.writestr(name, content)
    return planted


def pickle_stats(run: Path, marker: Path | None) -> None:
    """Replace every ``*vecnormalize.json`` by SB3's pickle format: the honest statistics, or the plant."""
    venv = env_spaces_venv(load_config(run), run / "config.yml")
    for path in run.rglob("*vecnormalize.json"):
        pkl = path.with_suffix(".pkl")
        if marker is None:
            load_stats(path, venv, training=False).save(str(pkl))
        else:
            pkl.write_bytes(pickle.dumps(Plant(marker)))
        path.unlink()


@pytest.fixture
def planted(tiny_run: Path, tmp_path: Path) -> tuple[Path, Path]:
    run, marker = tmp_path / "planted", tmp_path / "ran"
    shutil.copytree(tiny_run, run)
    assert plant_models(run, marker) >= 4 * 6  # final, best and two checkpoints; >= 6 entries each
    return run, marker


def exit_line(main, argv: list[str], capsys: pytest.CaptureFixture) -> str:
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_planted_models_load_without_running_the_plant(planted: tuple[Path, Path], train: ModuleType,
                                                       tmp_path: Path) -> None:
    run, marker = planted
    shutil.copy(run / "model.zip", tmp_path / "control.zip")
    assert SB3Policy.load(run).model.num_timesteps == 64 and SB3Policy.load(run, "best") is not None
    compare.run(["--model", str(run), *COMPARE, "--out", str(tmp_path / "compare")])
    assert (tmp_path / "compare" / "summary.md").is_file()
    track_video.main(["--synthetic", "--n-frames", "12", "--detector", "regions", "--tuned", str(run),
                      "--no-video", "--out", str(tmp_path / "track")])
    assert json.loads((tmp_path / "track" / "summary.json").read_text())["filter"] == "ufir_cmn"
    train.run(["--resume", str(run), "--timesteps", "96"])
    assert SB3Policy.load(run).model.num_timesteps == 96
    assert not marker.exists()
    naive(PPO.load, tmp_path / "control.zip", device="cpu")  # positive control
    assert marker.exists()


def test_pickled_statistics_are_refused_everywhere(tiny_run: Path, train: ModuleType, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    run, marker = tmp_path / "old", tmp_path / "ran"
    shutil.copytree(tiny_run, run)
    pickle_stats(run, marker)
    with pytest.raises(RunError, match="--trust-pickle"):
        SB3Policy.load(run)
    line = exit_line(compare.main, ["--model", str(run), *COMPARE, "--out", str(tmp_path / "c")], capsys)
    assert f"{run / 'vecnormalize.pkl'}: statistics stored as a pickle" in line and "--trust-pickle" in line
    line = exit_line(track_video.main, ["--synthetic", "--tuned", str(run), "--out", str(tmp_path / "t")], capsys)
    assert "vecnormalize.pkl" in line and "--trust-pickle" in line
    line = exit_line(train.main, ["--resume", str(run)], capsys)
    assert "no complete checkpoint" in line and "vecnormalize.pkl" in line and "--trust-pickle" in line
    assert not marker.exists() and not (tmp_path / "c").exists() and not (tmp_path / "t").exists()
    naive(VecNormalize.load, str(run / "vecnormalize.pkl"), env_spaces_venv(load_config(run), run / "config.yml"))
    assert marker.exists()


def test_trust_pickle_loads_an_honest_old_run_and_converts_it(tiny_run: Path, train: ModuleType, tmp_path: Path) -> None:
    run = tmp_path / "old"
    shutil.copytree(tiny_run, run)
    pickle_stats(run, None)
    assert not list(run.rglob("*vecnormalize.json"))
    track_video.main(["--synthetic", "--n-frames", "12", "--detector", "regions", "--tuned", str(run),
                      "--trust-pickle", "--no-video", "--out", str(tmp_path / "track")])
    assert (run / "vecnormalize.json").is_file()
    train.run(["--resume", str(run), "--timesteps", "96", "--trust-pickle"])
    assert (run / "checkpoints" / "ckpt_000000000064" / "vecnormalize.json").is_file()
    assert SB3Policy.load(run).model.num_timesteps == 96  # no pickle needed any more
