"""Results across training seeds: IQM and mean with stratified bootstrap CIs, and performance profiles.

The estimator of rliable (Agarwal et al., "Deep Reinforcement Learning at the Edge of the Statistical Precipice",
NeurIPS 2021), written here (the ``rliable`` package pulls pandas, statsmodels, arch and seaborn): a score matrix
(R runs = training seeds) × (T tasks) is summarised by its interquartile mean (the 25 % trimmed mean of all R·T
scores) and its mean; a **stratified bootstrap** resample draws, for every task independently, R runs with
replacement, and the CI is the percentile interval of the statistic over the resamples. The CI therefore shows
the variability of training, for this fixed set of tasks. A performance profile is the fraction of all R·T
scores above τ, as a function of τ, with the same resampling for its band.

Tasks here are the test episodes (sim, video) or the test sequences (OTB sources: a run's score on a sequence is
the mean over that sequence's episodes), so episodes of one sequence are not counted as independent tasks.

>>> scores = np.array([[0.0, 1.0, 2.0, 3.0], [4.0, 5.0, 6.0, 7.0]])  # 2 runs x 4 tasks
>>> float(iqm_all(scores))  # the middle half of 0 … 7: 2, 3, 4, 5
3.5
>>> [float(v) for v in profile(scores, np.array([-1.0, 3.0, 7.0]))]  # share of scores > tau
[1.0, 0.5, 0.0]
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.stats import trim_mean

from bboxtune.agents.evaluation.stats import fmt_ci

MatrixStat = Callable[[np.ndarray], np.ndarray]  # (..., R, T) -> (...)


def iqm_all(scores: np.ndarray) -> np.ndarray:
    """IQM of all R·T scores of ``scores`` (..., R, T): the 25 % trimmed mean over the last two axes."""
    flat = scores.reshape(*scores.shape[:-2], -1)
    return trim_mean(flat, 0.25, axis=-1)


def mean_all(scores: np.ndarray) -> np.ndarray:
    """Mean of all R·T scores of ``scores`` (..., R, T)."""
    return scores.mean(axis=(-2, -1))


def profile(scores: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """Performance profile: for each τ of ``taus`` (K,), the fraction of the scores (..., R, T) above τ → (..., K)."""
    flat = scores.reshape(*scores.shape[:-2], -1)
    return (flat[..., None, :] > taus[:, None]).mean(axis=-1)


def stratified_resamples(scores: np.ndarray, n_boot: int, seed: int) -> np.ndarray:
    """``n_boot`` stratified bootstrap resamples (n_boot, R, T) of ``scores`` (R, T): for every task (column)
    independently, R runs drawn with replacement."""
    R, T = scores.shape
    rows = np.random.default_rng(seed).integers(R, size=(n_boot, R, T))
    return scores[rows, np.arange(T)]


def stratified_ci(scores: np.ndarray, stat: MatrixStat, n_boot: int, seed: int,
                  level: float = 0.95) -> tuple[float, float, float]:
    """(estimate, low, high): ``stat`` of ``scores`` (R, T) and its percentile CI over stratified resamples."""
    values = stat(stratified_resamples(scores, n_boot, seed))
    tail = 100 * (1 - level) / 2
    return float(stat(scores[None])[0]), float(np.percentile(values, tail)), float(np.percentile(values, 100 - tail))


def score_matrix(rows: Sequence[dict[str, Any]], methods: Sequence[str], key: str) -> np.ndarray:
    """The (R, T) matrix of ``key`` for ``methods`` (one per run) over the tasks: episodes, or the sequences'
    means where the rows name a sequence. Every method must have every task."""
    per_method: list[np.ndarray] = []
    for method in methods:
        tasks: dict[Any, list[float]] = {}
        for row in rows:
            if row["method"] == method:
                task = row.get("sequence") or row["episode"]
                tasks.setdefault(task, []).append(float(row[key]))
        per_method.append(np.array([np.mean(tasks[t]) for t in sorted(tasks, key=str)]))
    if len({len(v) for v in per_method}) != 1:
        raise ValueError(f"methods {list(methods)} were not scored on the same tasks")
    return np.stack(per_method)


def seeds_section(rows: Sequence[dict[str, Any]], groups: dict[str, list[str]], *, n_boot: int, seed: int,
                  reference: Sequence[str] = ()) -> str:
    """Markdown: per group (a method trained with several seeds: its per-seed method names), the IQM and the
    mean of the log-ratio vs the rule and of the RMSE, with stratified bootstrap CIs; ``reference`` methods
    (one run each: raw, rule, oracle, …) are shown alongside as one-run rows."""
    head = ["## Across training seeds (IQM and mean, stratified bootstrap)", "",
            "rliable's estimator (`bboxtune.agents.evaluation.seeds_report`): tasks = test "
            f"{'sequences' if any(r.get('sequence') for r in rows) else 'episodes'}; "
            f"each of {n_boot} resamples draws, per task, the runs (seeds) with replacement; 95 % percentile CIs. "
            "Reference methods are one run each (their CI is 0 wide).", "",
            "| method | runs | log-ratio IQM | log-ratio mean | RMSE IQM (px) | RMSE mean (px) |", "|---|---|---|---|---|---|"]
    lines = []
    for name, methods in [*groups.items(), *[(m, [m]) for m in reference]]:
        cells = []
        for key in ("log_ratio", "rmse"):
            scores = score_matrix(rows, methods, key)
            for stat in (iqm_all, mean_all):
                cells.append(fmt_ci(*stratified_ci(scores, stat, n_boot, seed), signed=key == "log_ratio"))
        lines.append(f"| {name} | {len(methods)} | " + " | ".join(cells) + " |")
    return "\n".join(head + lines) + "\n"


def profile_curves(rows: Sequence[dict[str, Any]], groups: dict[str, list[str]], *, n_boot: int, seed: int
                   ) -> tuple[np.ndarray, dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, int]]]:
    """Performance profiles of the log-ratio vs the rule per group: τ (101,) over the 1st–99th percentile of all
    scores, and per group (profile, 2.5 % band, 97.5 % band, runs) from stratified resamples."""
    matrices = {name: score_matrix(rows, methods, "log_ratio") for name, methods in groups.items()}
    values = np.concatenate([m.ravel() for m in matrices.values()])
    taus = np.linspace(np.percentile(values, 1), np.percentile(values, 99), 101)
    curves = {}
    for name, scores in matrices.items():
        bands = profile(stratified_resamples(scores, n_boot, seed), taus)
        curves[name] = (profile(scores[None], taus)[0], np.percentile(bands, 2.5, axis=0),
                        np.percentile(bands, 97.5, axis=0), len(scores))
    return taus, curves
