"""Misuse of train.py, compare.py and track_video.py: exit 2, one line naming the flag or file, no traceback,
nothing written (the contract and the placeholders are in ``cli_misuse.py``). Extra placeholders here: ``{run}``
a finished tiny run, ``{bad_config}`` a run folder whose config.yml is malformed YAML (line 2), ``{no_model}`` a
run folder with a valid config.yml and no model, ``{retune}`` a run of FilterRetune-v0 (config only).
Misuses that get as far as taking a run's lock (which records the pid in ``train.lock``), e.g. a resume target
below the steps done, are tested in ``test_train.py``."""

from __future__ import annotations

import importlib
import shutil
from pathlib import Path

import pytest
import yaml

from .cli_misuse import MisusePaths, check_misuse, misuse, run_script

COUNT = ("0", "-1", "abc", "1_0", "2.5")  # not integers >= 1 ("1_0" is 10 to int())

TRAIN = [
    *[misuse(flag, v) for flag in ("--timesteps", "--n-envs", "--eval-freq", "--eval-episodes", "--checkpoint-freq")
      for v in COUNT],
    misuse("--seed", "-1"), misuse("--seed", "abc"), misuse("--algo", "dqn"), misuse("--backend", "nope"),
    misuse("--source", "nope"), misuse("--reward", "nope"), misuse("--timesteps"),
    misuse("--out", "{under_file}"), misuse("--out", "{file}"), misuse("--out", "{run}", mentions="not empty"),
    misuse("--resume", "{missing}"), misuse("--resume", "{file}"),
    misuse("--resume", "{dir}", mentions="{dir} is not a train.py run directory"),
    misuse("--resume", "{bad_config}", mentions="{bad_config}/config.yml:2:"),
    misuse("--resume", "{run}", "--backend", "kf"), misuse("--resume", "{run}", "--out", "{out}", mentions="--out"),
    misuse("--trust-pickle"),
    misuse("--hyperparams", "n_steps", mentions="--hyperparams 'n_steps': expected KEY:VALUE"),
    misuse("--hyperparams", "n_steps:[1", mentions="not valid YAML"),
    misuse("--hyperparams", "n_steps:8", "n_steps:16", mentions="n_steps given twice"),
    misuse("--hyperparams", "bogus_key:1", mentions="bogus_key"),
    misuse("--hyperparams", "vec_env:threads", mentions="vec_env='threads'"),
    misuse("--vec", "threads"), misuse("--vec", "batched", "--hyperparams", "vec_env:dummy", mentions="--vec: given twice"),
    misuse("--vec", "batched", "--env", "bboxtune/FilterRetune-v0", mentions="vec_env='batched' exists for"),
    misuse("--env-kwargs", "track_length:3", mentions="track_length=3"),
    misuse("--env-kwargs", "track_length:abc", mentions="track_length"),
    misuse("--env-kwargs", "nope:1", mentions="nope"),
    misuse("--env-kwargs", "backend:kf", mentions="--env-kwargs ['backend']"),
    misuse("--env", "bboxtune/NoSuch-v0", mentions="NoSuch"),
    *[misuse("--trackers", v) for v in ("", ",", "SiamFC,SiamFC", "a,,b")],
    misuse("--trackers", "test", "--env-kwargs", "trackers=[SiamFC]", mentions="--trackers: given twice"),
    misuse("--timesteps", "64", "--backend", "kf", "--source", "otb", mentions="otb"),  # no OTB data ($OTB_ROOT unset)
]
COMPARE = [
    misuse(mentions="--model"), misuse("--model", "{missing}"), misuse("--model", "{file}"),
    misuse("--model", "{dir}", mentions="{dir} is not a train.py run directory"),
    misuse("--model", "{bad_config}", mentions="{bad_config}/config.yml:2:"),
    misuse("--model", "{no_model}", mentions="{no_model}/model.zip not found"),
    misuse("--model", "{retune}", mentions="{retune}/model.zip not found"),  # FilterRetune-v0 runs are scored too
    misuse("--model", "{run}", "--oneshot-model", "{run}", mentions="--oneshot-model: only for runs of bboxtune/FilterRetune-v0"),
    misuse("--model", "{kf_config}", mentions="{kf_config}/model.zip was trained on"),
    *[misuse("--model", "{run}", flag, v) for flag in ("--episodes", "--global-trials", "--oracle-budget", "--bootstrap")
      for v in COUNT],
    misuse("--model", "{run}", "--episodes", "2000000000"), misuse("--model", "{run}", "--train-episodes", "10"),
    misuse("--model", "{run}", "--seed", "-1"),
    misuse("--model", "{run}", "--out", "{under_file}"), misuse("--model", "{run}", "--out", "{file}"),
    misuse("--model", "{run}", "--out", "{run}", mentions="not empty"),
]
TRACK_VIDEO = [
    misuse(mentions="--synthetic"), misuse("--synthetic", "--video", "{file}", mentions="--video"),
    misuse("--video", "{missing}"), misuse("--video", "{dir}"),
    misuse("--video", "{file}", mentions="{file}: not a readable video"),
    misuse("--frames", "{missing}"), misuse("--frames", "{file}"), misuse("--frames", "{dir}", mentions="{dir}"),
    *[misuse("--synthetic", "--init", v) for v in ("1,2,3", "a,b,c,d", "1,2,0,4", "nan,1,2,3", "")],
    *[misuse("--synthetic", "--n-frames", v) for v in (*COUNT, "1")],
    misuse("--synthetic", "--n-frames", "100001"),  # was allowed up to 10**6: 72.8 GiB MemoryError in the rendering
    misuse("--synthetic", "--seed", "-1"), misuse("--synthetic", "--detector", "surf"),
    misuse("--synthetic", "--filter", "nope"),
    misuse("--synthetic", "--tuned", "{missing}", mentions="--tuned"),
    misuse("--synthetic", "--tuned", "{dir}", mentions="neither a train.py run directory"),
    misuse("--synthetic", "--tuned", "{bad_json}", mentions="{bad_json}:2:"),
    misuse("--synthetic", "--tuned", "{file}", mentions="{file}:1:"),
    misuse("--synthetic", "--tuned", "{bad_config}", mentions="{bad_config}/config.yml:2:"),
    misuse("--synthetic", "--tuned", "{no_model}", mentions="{no_model}/model.zip not found"),
    misuse("--synthetic", "--tuned", "{run}", "--filter", "kf", mentions="--filter kf differs"),
    misuse("--synthetic", "--tuned", "{kf_config}", mentions="{kf_config}/model.zip was trained on"),
    misuse("--synthetic", "--out", "{under_file}"), misuse("--synthetic", "--out", "{file}"),
    misuse("--synthetic", "--out", "{run}", mentions="not empty"),
    misuse("--synthetic", "--sequence", "Car4", mentions="--sequence"),
    misuse("--synthetic", "--otb-root", "{missing}"),
]
PARAMS = [pytest.param(name, case, id=f"{name}: {case}")
          for name, cases in (("train", TRAIN), ("compare", COMPARE), ("track_video", TRACK_VIDEO)) for case in cases]


@pytest.fixture
def run_paths(misuse_paths: MisusePaths, tiny_run: Path) -> MisusePaths:
    root = misuse_paths.root
    shutil.copytree(tiny_run, root / "run")
    config = yaml.safe_load((tiny_run / "config.yml").read_text())
    for name, text in (("bad_config", "algo: ppo\nenv_id: x: y\nseed: 0\n"), ("no_model", yaml.safe_dump(config)),
                       ("retune", yaml.safe_dump({**config, "env_id": "bboxtune/FilterRetune-v0",  # as a retune run
                                                  "env_kwargs": {**config["env_kwargs"], "features": "base"}}))):
        (root / name).mkdir()
        (root / name / "config.yml").write_text(text)
    shutil.copytree(tiny_run, root / "kf_config")  # its config.yml edited to another back end of the same action size
    (root / "kf_config" / "config.yml").write_text(yaml.safe_dump({**config, "env_kwargs": {**config["env_kwargs"],
                                                                                             "backend": "kf"}}))
    names = {k: str(root / k) for k in ("run", "bad_config", "no_model", "retune", "kf_config")}
    return MisusePaths(root, misuse_paths.work, {**misuse_paths.names, **names})


@pytest.mark.parametrize(("name", "case"), PARAMS)
def test_misuse_exits_2_with_one_line_and_writes_nothing(name, case, run_paths, capsys, monkeypatch):
    check_misuse(importlib.import_module(f"bboxtune.agents.commands.{name}").main, case, run_paths, capsys, monkeypatch)


def test_misuse_from_the_command_line(misuse_paths: MisusePaths) -> None:
    done = run_script("compare", "--model", misuse_paths.names["dir"], cwd=misuse_paths.work)
    assert done.returncode == 2 and done.stdout == "" and "Traceback" not in done.stderr
    (line,) = done.stderr.splitlines()
    assert line.startswith("compare.py: error: ") and "is not a train.py run directory" in line
