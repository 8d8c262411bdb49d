"""Bootstrap statistics and the comparison report."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from agents.report import FIRST_COLUMNS, by_method, summary_markdown, write_results_csv
from agents.stats import STATS, bootstrap_indices, ci, iqm, win_rate


def test_iqm_ignores_the_tails() -> None:
    x = np.r_[np.arange(8.0), 1e9]
    assert iqm(x) < 10 and iqm(np.arange(8.0)) == 3.5


def test_bootstrap_interval_covers_the_mean_of_a_known_sample() -> None:
    x = np.random.default_rng(0).normal(1.0, 1.0, 400)
    est, lo, hi = ci(x, STATS["mean"], bootstrap_indices(400, 1000, seed=1))
    assert lo < est < hi and lo < 1.0 < hi and 0.12 < hi - lo < 0.28  # ≈ 2 · 1.96 / √400 = 0.196


def test_paired_series_are_resampled_together() -> None:
    a = np.random.default_rng(0).normal(size=200)
    est, lo, hi = ci(np.stack([a, a + 0.5]), lambda x: (x[..., 1, :] - x[..., 0, :]).mean(-1), bootstrap_indices(200, 300, 0))
    assert est == lo == hi == 0.5  # a paired difference that is constant has no sampling spread


def test_win_rate_counts_ties_half() -> None:
    assert win_rate(np.array([1.0, 2.0, 3.0, 0.5]), np.array([2.0, 2.0, 2.0, 1.0])) == 0.625


def _rows() -> list[dict]:
    rng = np.random.default_rng(0)
    rule = rng.uniform(2, 5, 40)
    rmse = {"rule": rule, "oracle": rule * 0.7, "ppo": rule * rng.uniform(0.7, 0.95, 40), "global": rule * 1.01}
    return [{"method": m, "backend": "ufir_cmn", "episode": e, "noise_seed": 10**9 + e, "rmse": float(v[e]),
             "rule_rmse": float(rule[e]), "log_ratio": float(np.log(rule[e] / v[e])), "success_auc": 0.8,
             "precision20": 0.9, "iou_mean": 0.7, "iou_precision": 0.6, "true_psi": e / 40}
            for m, v in rmse.items() for e in range(40)]


def test_results_csv_columns(tmp_path: Path) -> None:
    write_results_csv(tmp_path / "r.csv", _rows())
    with open(tmp_path / "r.csv") as fh:
        header = next(csv.reader(fh))
    assert tuple(header[: len(FIRST_COLUMNS)]) == FIRST_COLUMNS and "true_psi" in header


def test_summary_tables() -> None:
    rows = _rows()
    text = summary_markdown(rows, {"oracle": "y (truth)"}, learned=["ppo"], title="T", settings={"episodes": 40},
                            figures=["a.png"], n_boot=200)
    assert "| oracle | y (truth) | +0.357" in text  # log(1/0.7) = 0.357
    assert "| global | n | -0.010" in text and "## Paired: ppo against each method" in text
    gap = by_method(rows, "log_ratio")
    closed = gap["ppo"].mean() / gap["oracle"].mean()
    assert f"+{closed:.2f} [" in text and "ψ ∈ [0.6, 1.0)" in text and "![a.png](a.png)" in text
