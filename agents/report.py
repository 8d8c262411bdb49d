"""``results.csv`` and ``summary.md`` of ``scripts/compare.py`` from per-episode records.

Definitions (per test episode e, method m; RMSE in px over all frames of (cx, cy, w, h)):

* log-ratio  g_m,e = log(RMSE_rule,e / RMSE_m,e) — the env's reward; > 0: better than the rule;
* win rate   P(RMSE_m < RMSE_rule) + ½ P(equal) over episodes (probability of improvement);
* regret     log(RMSE_m,e / RMSE_oracle,e) ≥ 0 (mean over episodes);
* gap closed mean_e g_m,e / mean_e g_oracle,e: the fraction of the rule → oracle gap (in log RMSE) closed.

Confidence intervals are 95 % percentile bootstraps over episodes, paired across methods (:mod:`agents.stats`).
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.stats import STATS, bootstrap_indices, ci, fmt_ci, win_rate

FIRST_COLUMNS = ("method", "backend", "episode", "noise_seed", "rmse", "rule_rmse", "log_ratio", "success_auc",
                 "precision20", "iou_mean", "iou_precision")
PSI_STRATA = ((0.0, 0.3), (0.3, 0.6), (0.6, 1.0))


def write_results_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """One row per method × episode; the columns of :data:`FIRST_COLUMNS` first, then parameters and truth."""
    extra = sorted({k for r in rows for k in r} - set(FIRST_COLUMNS))
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=[*FIRST_COLUMNS, *extra], restval="")
        writer.writeheader()
        writer.writerows(rows)


def by_method(rows: Sequence[dict[str, Any]], key: str) -> dict[str, np.ndarray]:
    """method -> values of ``key`` ordered by episode."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    return {m: np.array([r[key] for r in sorted((r for r in rows if r["method"] == m), key=lambda r: r["episode"])],
                        dtype=float) for m in methods}


def _table(header: Sequence[str], body: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return "\n".join(lines)


def summary_markdown(rows: Sequence[dict[str, Any]], truth_at_test: dict[str, str], *, learned: Sequence[str],
                     title: str, settings: dict[str, Any], figures: Sequence[str], n_boot: int = 2000,
                     seed: int = 0) -> str:
    """The summary tables of a comparison (see the module docstring for the definitions)."""
    rmse, gain = by_method(rows, "rmse"), by_method(rows, "log_ratio")
    auc, p20 = by_method(rows, "success_auc"), by_method(rows, "precision20")
    methods = list(rmse)
    n = len(rmse["rule"])
    idx = bootstrap_indices(n, n_boot, seed)
    oracle = rmse.get("oracle")
    out = [f"# {title}", "", *[f"- {k}: {v}" for k, v in settings.items()], ""]

    body = [[m, *(fmt_ci(*ci(rmse[m], STATS[s], idx), digits=2) for s in ("mean", "median", "iqm"))] for m in methods]
    out += ["## RMSE (px), 95 % bootstrap CI", "", _table(["method", "mean", "median", "IQM"], body), ""]

    header = ["method", "GT used at test", "log-ratio mean", "log-ratio median", "log-ratio IQM",
              "win rate vs rule", "regret vs oracle", "gap closed", "success AUC", "precision@20px"]
    body = []
    for m in methods:
        g = gain[m]
        win = ci(np.stack([rmse[m], rmse["rule"]]), lambda x: _win(x), idx)
        row = [m, truth_at_test.get(m, "n"), *(fmt_ci(*ci(g, STATS[s], idx), signed=True) for s in ("mean", "median", "iqm")),
               fmt_ci(*win, digits=2)]
        if oracle is not None:
            row.append(fmt_ci(*ci(np.log(rmse[m] / oracle), STATS["mean"], idx)))
            og = gain["oracle"]
            closed = ci(np.stack([g, og]), lambda x: x[..., 0, :].mean(-1) / x[..., 1, :].mean(-1), idx)
            row.append(fmt_ci(*closed, digits=2, signed=True) if og.mean() > 0 else "–")
        else:
            row += ["–", "–"]
        row += [f"{auc[m].mean():.4f}", f"{p20[m].mean():.4f}"]
        body.append(row)
    out += ["## Relative to the rule and the oracle", "", "log-ratio = log(RMSE_rule / RMSE) (> 0: better than the "
            "rule); regret = mean log(RMSE / RMSE_oracle); gap closed = mean log-ratio / oracle's mean log-ratio.",
            "", _table(header, body), ""]

    for L in learned:
        body = []
        for m in methods:
            if m == L:
                continue
            d = ci(gain[L] - gain[m], STATS["mean"], idx)
            body.append([m, fmt_ci(*d, signed=True), f"{win_rate(rmse[L], rmse[m]):.2f}",
                         "yes" if d[1] > 0 or d[2] < 0 else "no"])
        out += [f"## Paired: {L} against each method", "", f"Δ = log(RMSE_method / RMSE_{L}) per episode (> 0: {L} better).",
                "", _table(["method", "mean Δ [95 % CI]", f"P({L} better)", "CI excludes 0"], body), ""]

    psi = by_method(rows, "true_psi")["rule"] if rows and "true_psi" in rows[0] else None
    if psi is not None:
        header = ["method", *(f"ψ ∈ [{lo}, {hi})  (n={int(np.sum((psi >= lo) & (psi < hi)))})" for lo, hi in PSI_STRATA)]
        body = [[m, *(f"{gain[m][(psi >= lo) & (psi < hi)].mean():+.3f}" if np.any((psi >= lo) & (psi < hi)) else "–"
                      for lo, hi in PSI_STRATA)] for m in methods]
        out += ["## Mean log-ratio by true ψ (analysis only)", "", _table(header, body), ""]
    out += ["## Figures", "", *[f"![{f}]({f})" for f in figures], ""]
    return "\n".join(out)


def _win(x: np.ndarray) -> np.ndarray:
    """Win rate of row 0 over row 1 along the last axis; ``x`` (..., 2, n)."""
    a, b = x[..., 0, :], x[..., 1, :]
    return np.mean((a < b) + 0.5 * (a == b), axis=-1)
