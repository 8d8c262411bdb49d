"""agents/evaluation/seeds_report.py: rliable's IQM, stratified bootstrap and performance profile, on worked numbers."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune.agents.evaluation.seeds_report import (
    iqm_all,
    mean_all,
    profile,
    score_matrix,
    seeds_section,
    stratified_ci,
    stratified_resamples,
)


def test_iqm_of_a_worked_matrix() -> None:
    # 3 runs x 4 tasks: the 12 sorted scores 1..12; the middle half (25 % trimmed each side) is 4..9 -> 6.5
    scores = np.arange(1.0, 13.0).reshape(3, 4)[[2, 0, 1]]
    assert iqm_all(scores) == pytest.approx(6.5) and mean_all(scores) == pytest.approx(6.5)
    skewed = np.array([[0.0, 0.0, 0.0, 100.0], [1.0, 1.0, 1.0, 1.0]])  # sorted 0 0 | 0 1 1 1 | 1 100: the outlier
    assert iqm_all(skewed) == pytest.approx(0.75) and mean_all(skewed) == pytest.approx(13.0)  # is trimmed, not averaged


def test_stratified_resamples_draw_runs_within_each_task() -> None:
    scores = np.array([[0.0, 10.0, 20.0], [1.0, 11.0, 21.0]])  # task t holds 10 t + run
    draws = stratified_resamples(scores, 500, seed=0)
    assert draws.shape == (500, 2, 3)
    assert np.array_equal(np.floor(draws / 10), np.broadcast_to([0.0, 1.0, 2.0], draws.shape))  # never across tasks
    runs = draws % 10
    assert 0.4 < runs.mean() < 0.6 and not np.all(runs[:, :, 0] == runs[:, :, 1])  # tasks drawn independently


def test_identical_runs_give_a_zero_width_ci_and_different_runs_a_wide_one() -> None:
    same = np.tile(np.linspace(0, 1, 50), (5, 1))
    assert stratified_ci(same, iqm_all, 200, seed=1) == pytest.approx((0.5, 0.5, 0.5), abs=1e-12)
    rng = np.random.default_rng(2)
    spread = rng.normal(0.0, 1.0, (5, 50)) + rng.normal(0.0, 1.0, (5, 1))  # seeds differ as a whole
    est, low, high = stratified_ci(spread, mean_all, 2000, seed=3)
    assert low < est < high and high - low > 0.1


def test_profile_counts_scores_above_tau() -> None:
    scores = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    np.testing.assert_allclose(profile(scores, np.array([0.0, 0.25, 0.45, 0.6])), [1.0, 4 / 6, 2 / 6, 0.0])


def test_score_matrix_and_section_from_result_rows() -> None:
    rows = [{"method": m, "episode": e, "sequence": "", "log_ratio": v, "rmse": 1.0 - v}
            for m, values in (("ppo_s0", [0.1, 0.2]), ("ppo_s1", [0.3, 0.4]), ("rule", [0.0, 0.0]))
            for e, v in enumerate(values)]
    np.testing.assert_allclose(score_matrix(rows, ["ppo_s0", "ppo_s1"], "log_ratio"), [[0.1, 0.2], [0.3, 0.4]])
    text = seeds_section(rows, {"ppo": ["ppo_s0", "ppo_s1"]}, n_boot=100, seed=0, reference=("rule",))
    assert "| ppo | 2 | +0.250 [" in text and "| rule | 1 | +0.000 [+0.000, +0.000]" in text and "episodes" in text
    otb = [{**r, "sequence": f"Seq{r['episode'] // 2}"} for r in rows]  # OTB rows: tasks are sequences
    assert score_matrix(otb, ["ppo_s0"], "log_ratio").shape == (1, 1)
    with pytest.raises(ValueError, match="same tasks"):
        score_matrix(rows[:3], ["ppo_s0", "ppo_s1"], "log_ratio")
