"""scripts/train.py --backend bytetrack_kf (a 2,048-step run on 64-frame tracks: seconds) and scripts/compare.py on it:
the tuner sets ByteTrack's weights, the baselines it is compared with are those that apply (no σ rules), and the
rule is stock ByteTrack."""

from __future__ import annotations

import csv
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import yaml

from bboxtune.agents.commands import compare as compare_command
from bboxtune.agents.smoothing.tuner import Tuner
from bboxtune.envs.data.boxes import cxcywh_to_xywh
from bboxtune.envs.episodes.actions import STOCK

RUN = ["--backend", "bytetrack_kf", "--timesteps", "2000", "--n-envs", "32", "--hyperparams", "n_steps:64",
       "batch_size:512", "n_epochs:2", "--env-kwargs", "track_length:64", "--eval-freq", "1000", "--eval-episodes", "4",
       "--checkpoint-freq", "2000"]
FAST = ["--train-episodes", "24", "--global-trials", "8", "--oracle-budget", "16", "--bootstrap", "50", "--episodes", "6"]
METHODS = {"raw", "bytetrack_kf", "sort_kf", "rule", "oracle", "oracle_auc", "global", "amortised", "adaptive", "ppo", "ppo_best"}


@pytest.fixture(scope="module")
def run(train: ModuleType, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train.run([*RUN, "--out", str(tmp_path_factory.mktemp("runs") / "bytetrack")])


def test_the_run_tunes_bytetracks_weights(run: Path) -> None:
    cfg = yaml.safe_load((run / "config.yml").read_text())
    assert cfg["env_kwargs"]["backend"] == "bytetrack_kf" and (run / "model.zip").is_file()
    tuner = Tuner.from_run(run)
    t = np.arange(40.0)
    boxes = cxcywh_to_xywh(np.stack([100 + 2 * t, 80 + np.sin(t), 30 + 0 * t, 60 + 0.1 * t], axis=1))
    params = tuner.tune(boxes, 1 / 30)
    assert set(params) == set(STOCK) and params["std_aspect_measurement"] == STOCK["std_aspect_measurement"]
    assert np.isfinite(tuner.smooth(boxes, 1 / 30)).all()


def test_compare_scores_it_against_stock_bytetrack(run: Path, tmp_path: Path) -> None:
    out = compare_command.run(["--model", str(run), *FAST, "--out", str(tmp_path / "compare")])
    with open(out / "results.csv") as fh:
        table = list(csv.DictReader(fh))
    assert {r["method"] for r in table} == METHODS and len(table) == len(METHODS) * 6
    assert {r["backend"] for r in table} == {"bytetrack_kf"}
    assert {k for k in table[0] if k.startswith("param_")} == {f"param_{k}" for k in STOCK}
    for r in table:
        if r["method"] == "rule":
            assert float(r["log_ratio"]) == 0.0 and all(float(r[f"param_{k}"]) == v for k, v in STOCK.items())
        if r["method"] == "bytetrack_kf":  # the stock filter scored as a peer method is the rule of this back end
            assert float(r["log_ratio"]) == 0.0
        if r["method"] == "oracle":
            assert float(r["rmse"]) <= float(r["rule_rmse"])
    assert "backend bytetrack_kf" in (out / "summary.md").read_text()
