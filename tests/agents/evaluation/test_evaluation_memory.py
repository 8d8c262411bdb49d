"""The evaluation's memory estimate (``check_evaluation_memory``): its edge against a pinned available figure, and
within a factor 2 above the peak tracemalloc measures for records, results.csv and summary.md."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from bboxtune.agents.evaluation.evaluate import RECORD_BYTES, RESAMPLE_BYTES, SPEC_BYTES, check_evaluation_memory
from bboxtune.agents.evaluation.report import summary_markdown, write_results_csv
from bboxtune.envs.data import memory
from bboxtune.envs.data.memory import MemoryLimitError

METHODS = ["raw", "bytetrack_kf", "sort_kf", "rule", "rule_est_sigma", "rule_true_sigma", "oracle", "oracle_auc",
           "global", "amortised", "ppo", "ppo_best", "adaptive"]


def estimate(n: int, n_methods: int, n_boot: int) -> int:
    return n * (SPEC_BYTES + n_methods * RECORD_BYTES + n_boot * RESAMPLE_BYTES)


def test_the_edge_is_the_available_figure(monkeypatch):
    needed = estimate(1000, 14, 2000)
    monkeypatch.setattr(memory, "available_bytes", lambda: needed)
    check_evaluation_memory(1000, 14, 2000, "--episodes 1000")
    with pytest.raises(MemoryLimitError, match=r"^--episodes 1001 \(1001 episodes × 14 methods, 2000 bootstrap resamples\) "
                                               r"needs ~0.\d+ GiB, this machine has 0.\d+ GiB available$"):
        check_evaluation_memory(1001, 14, 2000, "--episodes 1001")


def records(n: int, rng: np.random.Generator) -> list[dict]:
    """Records shaped as ``evaluate`` writes them (sim source, a σ-tuning back end)."""
    return [{"method": name, "episode": i, "sequence": "", "tracker": "", "rmse": rng.random(), "success_auc": rng.random(),
             "precision20": rng.random(), "backend": "ufir_cmn", "source": "sim", "noise_seed": 10**9 + i,
             "rule_rmse": rng.random(), "log_ratio": rng.random(), "iou_mean": rng.random(), "iou_precision": rng.random(),
             **{f"param_{k}": rng.random() for k in ("psi", "horizon", "sigma_w", "sigma_v")},
             **{f"true_{k}": rng.random() for k in ("psi", "sigma_w", "sigma_xi", "tau")}}
            for i in range(n) for name in METHODS]


@pytest.mark.parametrize("n_boot", [100, 1000])
def test_the_estimate_is_within_a_factor_2_above_the_measured_peak(n_boot, tmp_path):
    n = 200
    tracemalloc.start()
    try:
        rows = records(n, np.random.default_rng(0))
        write_results_csv(tmp_path / "results.csv", rows)
        summary_markdown(rows, {m: "n" for m in METHODS}, learned=["ppo", "ppo_best"], title="t", settings={}, figures=[],
                         n_boot=n_boot)
        measured = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert measured <= estimate(n, len(METHODS), n_boot) <= 2 * measured, (measured, estimate(n, len(METHODS), n_boot))
