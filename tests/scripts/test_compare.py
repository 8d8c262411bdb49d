"""scripts/compare.py on a tiny run with a few episodes."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from .tiny_run import load_script, tiny_run, train  # noqa: F401  (fixtures)

REQUIRED = ("method", "backend", "episode", "rmse", "rule_rmse", "success_auc", "precision20")
METHODS = {"rule", "rule_est_sigma", "rule_true_sigma", "oracle", "global", "amortised", "adaptive", "ppo", "ppo_best"}
EPISODES = 6


@pytest.fixture(scope="module")
def compared(tiny_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("compare")
    load_script("compare").main(["--model", str(tiny_run), "--episodes", str(EPISODES), "--train-episodes", "24",
                                 "--global-trials", "8", "--oracle-budget", "16", "--bootstrap", "50", "--out", str(out)])
    return out


def test_results_csv(compared: Path) -> None:
    with open(compared / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert set(REQUIRED) <= set(rows[0])
    assert {r["method"] for r in rows} == METHODS and len(rows) == len(METHODS) * EPISODES
    assert {r["backend"] for r in rows} == {"ufir_cmn"}
    by = {m: {int(r["episode"]): r for r in rows if r["method"] == m} for m in METHODS}
    for e in range(EPISODES):
        rule = float(by["rule"][e]["rmse"])
        assert float(by["rule"][e]["log_ratio"]) == 0.0
        assert all(float(by[m][e]["rule_rmse"]) == rule for m in METHODS)
        assert float(by["oracle"][e]["rmse"]) <= min(rule, float(by["rule_true_sigma"][e]["rmse"]))
        assert np.isfinite(float(by["ppo"][e]["rmse"]))


def test_summary_and_figures(compared: Path) -> None:
    text = (compared / "summary.md").read_text()
    for needle in ("## RMSE (px)", "IQM", "win rate vs rule", "regret vs oracle", "success AUC", "precision@20px",
                   "GT used at test", "## Paired: ppo against each method", "| oracle | y (truth) |"):
        assert needle in text, needle
    for name in ("gain_boxplot.png", "otb_curves.png", "trajectory.png"):
        assert (compared / name).stat().st_size > 1000
