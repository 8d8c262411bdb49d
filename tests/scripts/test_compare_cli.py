"""Misuse of compare.py's evaluation flags (--env, --env-kwargs, --split, --episodes, --seeds-per-sequence) and of a
model in an env it cannot act in: exit 2, one line naming the flag or space, no traceback, nothing written (the
contract and the placeholders are in ``cli_misuse.py``; ``{run}`` is a finished tiny run of ufir_cmn on sim)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from bboxtune.agents.commands import compare

from .cli_misuse import MisusePaths, check_misuse, misuse

OTB = os.environ.get("OTB_ROOT", "")
WITH_OTB = {"OTB_ROOT": OTB}

CASES = [
    misuse("--episodes", "3", mentions="--model: required"),
    misuse("--env", "bboxtune/FilterTune-v0", "--out", "{out}", mentions="--model: required"),
    misuse("--env", "bboxtune/FilterRetune-v0", mentions="--out: required without --model"),
    misuse("--env", "bboxtune/FilterRetune-v0", "--env-kwargs", "window=0", "--out", "{out}", mentions="--env-kwargs"),
    misuse("--env", "bboxtune/FilterRetune-v0", "--regime-informed", "--out", "{out}",
           mentions="--regime-informed: needs source 'sim' with scenario=nonstationary"),
    misuse("--model", "{run}", "--regime-informed", mentions="--regime-informed: only for runs of bboxtune/FilterRetune-v0"),
    misuse("--model", "{run}", "--env-kwargs", "track_length=3", mentions="--env-kwargs: track_length=3"),
    misuse("--model", "{run}", "--env-kwargs", "track_length:abc", mentions="--env-kwargs: track_length='abc'"),
    misuse("--model", "{run}", "--env-kwargs", "nope=1", mentions="nope"),
    misuse("--model", "{run}", "--env-kwargs", "track_length", mentions="--env-kwargs 'track_length': expected KEY=VALUE"),
    misuse("--model", "{run}", "--env-kwargs", "psi_range=[0, 1", mentions="not valid YAML"),
    misuse("--model", "{run}", "--env-kwargs", "a=1", "a:2", mentions="a given twice"),
    misuse("--model", "{run}", "--env-kwargs", "split=val", mentions="--env-kwargs split"),
    misuse("--model", "{run}", "--env-kwargs", "backend=kf",
           mentions="action_space float32[2] sets ['psi', 'horizon'] of back end ufir_cmn"),
    misuse("--model", "{run}", "--env-kwargs", "backend=kf_cmn",
           mentions="action_space float32[2] of the model differs from the evaluation env's float32[3]"),
    misuse("--model", "{run}", "--env-kwargs", "tune=[horizon]", mentions="action_space float32[2] of the model differs"),
    misuse("--model", "{run}", "--env-kwargs", "horizon_max=100", mentions="horizon_max 400"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb", mentions="--env-kwargs"),  # $OTB_ROOT unset
    misuse("--model", "{run}", "--env", "bboxtune/FilterRetune-v0", mentions="--env"),
    misuse("--model", "{run}", "--env", "bboxtune/NoSuch-v0", mentions="--env"),
    misuse("--model", "{run}", "--fit-seeds", "2", mentions="--fit-seeds: only for runs of bboxtune/FilterRetune-v0"),
    *[misuse("--model", "{run}", "--fit-seeds", v) for v in ("0", "-1", "x")],
    misuse("--model", "{run}", "--split", "nope"), misuse("--model", "{run}", "--split"),
    misuse("--model", "{run}", "--seeds-per-sequence", "3", mentions="--seeds-per-sequence applies to source 'otb'"),
    *[misuse("--model", "{run}", "--seeds-per-sequence", v) for v in ("0", "-1", "abc", "1.5")],
    misuse("--model", "{run}", "--env-kwargs", "source=video", "--seeds-per-sequence", "2", mentions="--seeds-per-sequence"),
    misuse("--model", "{run}", "--episodes", "1000000000",  # the parser's maximum: ~90 TB of records and resamples
           mentions="--episodes 1000000000 (1000000000 episodes × 14 methods, 2000 bootstrap resamples) needs ~"),
    misuse("--model", "{run}", "--train-episodes", "1000000000",  # the baselines' train bank: ~40 TB at 500 frames
           mentions="--train-episodes 1000000000 (1000000000 episodes of up to"),
]
OTB_CASES = [
    misuse("--model", "{run}", "--env-kwargs", "source=otb", "--episodes", "5", env=WITH_OTB,
           mentions="--episodes: source 'otb' enumerates its episodes"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb_tracker", "--episodes", "5", env=WITH_OTB,
           mentions="--episodes: source 'otb_tracker'"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb_tracker", "--seeds-per-sequence", "2", env=WITH_OTB,
           mentions="--seeds-per-sequence"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb_tracker", "tracker=Nope", env=WITH_OTB, mentions="Nope"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb", "--split", "val", "--episodes", "3", env=WITH_OTB,
           mentions="every val-split sequence"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb_tracker", "--trackers", "SiamFC,Nope", env=WITH_OTB,
           mentions="--env-kwargs/--trackers: env"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb", "--trackers", "test", env=WITH_OTB,
           mentions="with source='otb'"),
    misuse("--model", "{run}", "--env-kwargs", "source=otb_tracker", "trackers=[SiamFC]", "--trackers", "test",
           env=WITH_OTB, mentions="--trackers: given twice"),
    *[misuse("--model", "{run}", "--trackers", v, env=WITH_OTB) for v in ("", ",", "SiamFC,SiamFC", "a,,b")],
    misuse("--model", "{run}", "--env-kwargs", "source=otb", "--seeds-per-sequence", "100000000", env=WITH_OTB,
           mentions="--seeds-per-sequence 100000000 ("),
]


@pytest.fixture
def run_paths(misuse_paths: MisusePaths, tiny_run: Path) -> MisusePaths:
    shutil.copytree(tiny_run, misuse_paths.root / "run")
    return MisusePaths(misuse_paths.root, misuse_paths.work, {**misuse_paths.names, "run": str(misuse_paths.root / "run")})


@pytest.mark.parametrize("case", CASES, ids=str)
def test_misuse_exits_2_with_one_line_and_writes_nothing(case, run_paths, capsys, monkeypatch) -> None:
    check_misuse(compare.main, case, run_paths, capsys, monkeypatch)


@pytest.mark.skipif(not OTB or not Path(OTB).is_dir(), reason="needs the OTB data ($OTB_ROOT)")
@pytest.mark.parametrize("case", OTB_CASES, ids=str)
def test_otb_misuse_exits_2_with_one_line_and_writes_nothing(case, run_paths, capsys, monkeypatch) -> None:
    check_misuse(compare.main, case, run_paths, capsys, monkeypatch)
