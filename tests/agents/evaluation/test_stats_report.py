"""Bootstrap statistics and the comparison report."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from bboxtune.agents.evaluation.report import (
    FIRST_COLUMNS,
    by_method,
    clusters,
    resampling_note,
    summary_markdown,
    write_results_csv,
)
from bboxtune.agents.evaluation.stats import (
    STATS,
    bootstrap_indices,
    ci,
    cluster_bootstrap_indices,
    iqm,
    paired_mean_ci,
    win_rate,
)


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


def test_paired_mean_ci_draws_from_the_given_generator_in_turn() -> None:
    """The video tables' interval: successive calls on one generator take successive draws, and the numbers are
    those of the resampling written out (rng.integers(0, n, (reps, n)), then the 2.5 / 97.5 percentiles)."""
    diffs = [np.array([0.1, -0.2, 0.3, 0.05, 0.0]), np.array([1.0, 2.0, 4.0])]
    rng, reference = np.random.default_rng(7), np.random.default_rng(7)
    for diff in diffs:
        means = diff[reference.integers(0, len(diff), (2000, len(diff)))].mean(axis=1)
        assert paired_mean_ci(diff, rng) == tuple(float(v) for v in np.percentile(means, [2.5, 97.5]))
    assert bootstrap_indices(5, 3, seed=7).tolist() == np.random.default_rng(7).integers(5, size=(3, 5)).tolist()


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


def test_every_episode_its_own_cluster_is_the_episode_bootstrap() -> None:
    idx = cluster_bootstrap_indices([f"episode {e}" for e in range(30)], 200, seed=5)
    np.testing.assert_array_equal(idx, bootstrap_indices(30, 200, seed=5))


def test_clusters_are_resampled_whole() -> None:
    labels = ["a"] * 3 + ["b"] * 1 + ["c"] * 2  # unequal sizes: a list of resamples
    idx = cluster_bootstrap_indices(labels, 100, seed=0)
    assert isinstance(idx, list) and len(idx) == 100
    members = {"a": {0, 1, 2}, "b": {3}, "c": {4, 5}}
    for sample in idx:
        counts = {k: sum(int(i in m) for i in sample) for k, m in members.items()}
        assert sum(counts[k] // len(members[k]) for k in members) == 3  # 3 clusters drawn, each whole
        assert all(counts[k] % len(members[k]) == 0 for k in members)


def test_cluster_ci_is_wider_than_the_episode_ci_when_episodes_repeat_a_sequence() -> None:
    """8 sequences × 25 episodes that mostly share their sequence's value: 200 episodes, 8 independent units."""
    rng = np.random.default_rng(0)
    labels = [f"s{c}" for c in range(8) for _ in range(25)]
    x = np.repeat(rng.normal(0.0, 1.0, 8), 25) + rng.normal(0.0, 0.05, 200)
    _, lo_e, hi_e = ci(x, STATS["mean"], bootstrap_indices(200, 1000, seed=1))
    est, lo_c, hi_c = ci(x, STATS["mean"], cluster_bootstrap_indices(labels, 1000, seed=1))
    assert lo_c < est < hi_c and hi_c - lo_c > 3 * (hi_e - lo_e)  # ≈ √25 = 5 times wider


def test_ragged_resamples_give_the_same_interval_as_the_equal_size_path() -> None:
    x = np.random.default_rng(2).normal(size=12)
    labels = [e // 3 for e in range(12)]  # 4 clusters of 3: an array
    idx = cluster_bootstrap_indices(labels, 300, seed=3)
    assert isinstance(idx, np.ndarray)
    assert ci(x, STATS["iqm"], idx) == pytest.approx(ci(x, STATS["iqm"], list(idx)))


def _otb_rows() -> list[dict]:
    rng = np.random.default_rng(1)
    rows = []
    for e, (seq, tracker) in enumerate((s, t) for s in ("Basketball", "Deer", "Vase") for t in ("A", "B")):
        auc = {"raw": 0.6, "rule": 0.55, "ppo": 0.6 + (0.02 if seq == "Deer" else 0.0), "oracle": 0.65}
        for m, a in auc.items():
            rows.append({"method": m, "episode": e, "sequence": seq, "tracker": tracker, "source": "otb_tracker",
                         "rmse": float(rng.uniform(2, 4)), "rule_rmse": 3.0, "log_ratio": 0.1, "success_auc": a,
                         "precision20": a + 0.2})
    return rows


def test_otb_summary_names_clusters_attributes_and_trackers() -> None:
    rows = _otb_rows()
    attributes = {"Basketball": frozenset({"OCC"}), "Deer": frozenset({"MB", "FM"}), "Vase": frozenset({"SV"})}
    text = summary_markdown(rows, {}, learned=["ppo"], title="T", settings={}, figures=[], n_boot=100,
                            attributes=attributes)
    assert "resamples of sequences (3 clusters; every drawn sequence brings all its episodes, 6 in all)" in text
    assert "| ppo | 0.6067 [" in text and "+0.0067 [" in text  # AUC and Δ vs raw: one sequence of three gains 0.02
    assert "MB (n=1)" in text and "OCC (n=1)" in text and "IV (n=0)" in text
    mb = [line for line in text.splitlines() if line.startswith("| ppo |") and "+0.0200" in line]
    assert mb, "the per-attribute Δ of ppo on MB (Deer only) is +0.02"
    assert "| A | raw | 0.6000 | 0.8000 | +0.0000 [+0.0000, +0.0000]" in text and "| B | ppo |" in text


def test_results_csv_is_written_atomically_with_the_key_columns_first(tmp_path: Path) -> None:
    write_results_csv(tmp_path / "r.csv", _otb_rows())
    assert [p.name for p in tmp_path.iterdir()] == ["r.csv"]
    with open(tmp_path / "r.csv") as fh:
        header = next(csv.reader(fh))
    assert header[:7] == ["method", "episode", "sequence", "tracker", "rmse", "success_auc", "precision20"]


def test_resampling_note_names_the_unit_and_the_clusters() -> None:
    assert "of episodes (3 clusters: every episode its own)" in resampling_note(["episode 0", "episode 1", "episode 2"], 9)
    mixed = resampling_note(["sequence A", "sequence A", "episode 2", "sequence B"], 9)
    assert "3 clusters: 2 sequences, each with all its episodes, and 1 episodes without a sequence" in mixed
    assert clusters([{"method": "rule", "episode": 1, "sequence": ""}, {"method": "rule", "episode": 0, "sequence": "A"},
                     {"method": "raw", "episode": 0, "sequence": "A"}]) == ["sequence A", "episode 1"]
