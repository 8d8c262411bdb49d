"""``results.csv`` and ``summary.md`` of ``scripts/compare.py`` from per-episode records.

Definitions (per test episode e, method m; RMSE in px over all frames of (cx, cy, w, h)):

* log-ratio  g_m,e = log(RMSE_rule,e / RMSE_m,e) — the env's reward; > 0: better than the rule;
* win rate   P(RMSE_m < RMSE_rule) + ½ P(equal) over episodes (probability of improvement);
* regret     log(RMSE_m,e / RMSE_oracle,e) ≥ 0 (mean over episodes), oracle = the RMSE ceiling (``oracle`` when
  the env's reward is RMSE, else ``oracle_rmse``);
* gap closed mean_e g_m,e / mean_e g_oracle,e: the fraction of the rule → oracle gap (in log RMSE) closed;
* Δ AUC      success AUC_m,e − success AUC_ref,e (ref = ``raw`` or ``rule``), precision@20px likewise.

Confidence intervals are 95 % percentile bootstraps, paired across methods, over *clusters* of episodes
(:func:`bboxtune.agents.evaluation.stats.cluster_bootstrap_indices`): the sequence of an episode (an OTB sequence
with all its noise
seeds and trackers, a synthetic video with all its episodes), or the episode itself when it has none (sim). The
summary names the resampled unit and the number of clusters. Sources other than sim add success-AUC / precision
tables against ``raw`` and ``rule``; OTB sources per-attribute success-AUC deltas (:mod:`bboxtune.agents.evaluation.report_otb`)
and, for "otb_tracker", rows per tracker.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bboxtune.agents.evaluation.records import by_method, episode_column, table
from bboxtune.agents.evaluation.report_otb import attribute_tables, auc_table, tracker_table
from bboxtune.agents.evaluation.stats import STATS, Resamples, ci, cluster_bootstrap_indices, fmt_ci, n_clusters, win_rate
from bboxtune.envs.data.atomic_files import write_text_atomic

FIRST_COLUMNS = ("method", "episode", "sequence", "tracker", "rmse", "success_auc", "precision20", "backend", "source",
                 "noise_seed", "rule_rmse", "log_ratio", "iou_mean", "iou_precision")
PSI_STRATA = ((0.0, 0.3), (0.3, 0.6), (0.6, 1.0))


def write_results_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """One row per method × episode; the columns of :data:`FIRST_COLUMNS` first, then parameters and truth;
    written atomically."""
    extra = sorted({k for r in rows for k in r} - set(FIRST_COLUMNS))
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=[*FIRST_COLUMNS, *extra], restval="")
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(path, text.getvalue())


def clusters(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The bootstrap cluster of each episode: its sequence, or the episode itself when it has none."""
    return [f"sequence {s}" if s else f"episode {e}" for s, e in zip(episode_column(rows, "sequence"),
                                                                      episode_column(rows, "episode"), strict=False)]


def resampling_note(labels: Sequence[str], n_boot: int) -> str:
    """What the bootstrap resamples (the unit and the number of clusters), for the summary's settings."""
    n, c = len(labels), n_clusters(labels)
    lone = sum(1 for label in labels if label.startswith("episode "))
    if lone == n:
        unit = f"episodes ({c} clusters: every episode its own)"
    elif lone == 0:
        unit = f"sequences ({c} clusters; every drawn sequence brings all its episodes, {n} in all)"
    else:  # a mix: OTB / video sequences and simulated episodes
        unit = (f"sequences and episodes ({c} clusters: {c - lone} sequences, each with all its episodes, and {lone} "
                "episodes without a sequence)")
    return f"95 % percentile bootstrap, {n_boot} resamples of {unit}, paired across methods"


def summary_markdown(rows: Sequence[dict[str, Any]], truth_at_test: dict[str, str], *, learned: Sequence[str],
                     title: str, settings: dict[str, Any], figures: Sequence[str], n_boot: int = 2000,
                     seed: int = 0, rmse_oracle: str = "oracle",
                     attributes: dict[str, frozenset[str]] | None = None) -> str:
    """The summary tables of a comparison (see the module docstring for the definitions); ``rmse_oracle``: the
    method whose RMSE is the ceiling; ``attributes``: OTB attribute flags per sequence (adds their tables)."""
    labels = clusters(rows)
    idx = cluster_bootstrap_indices(labels, n_boot, seed)
    settings = {**settings, "confidence intervals": resampling_note(labels, n_boot)}
    out = [f"# {title}", "", *[f"- {k}: {v}" for k, v in settings.items()], ""]
    out += _rmse_tables(rows, truth_at_test, learned, idx, rmse_oracle)
    if any(r.get("source", "sim") != "sim" for r in rows):
        out += auc_table(rows, idx)
    sequences = episode_column(rows, "sequence")
    if attributes is not None and any(sequences):
        out += attribute_tables(rows, attributes)
    if any(episode_column(rows, "tracker")):
        out += tracker_table(rows, learned, n_boot, seed)
    psi = by_method(rows, "true_psi")["rule"] if any("true_psi" in r for r in rows) else None
    if psi is not None:
        gain, methods = by_method(rows, "log_ratio"), list(by_method(rows, "rmse"))
        header = ["method", *(f"ψ ∈ [{lo}, {hi})  (n={int(np.sum((psi >= lo) & (psi < hi)))})" for lo, hi in PSI_STRATA)]
        body = [[m, *(f"{gain[m][(psi >= lo) & (psi < hi)].mean():+.3f}" if np.any((psi >= lo) & (psi < hi)) else "–"
                      for lo, hi in PSI_STRATA)] for m in methods]
        out += ["## Mean log-ratio by true ψ (analysis only)", "", table(header, body), ""]
    out += ["## Figures", "", *[f"![{f}]({f})" for f in figures], ""]
    return "\n".join(out)


def _rmse_tables(rows: Sequence[dict[str, Any]], truth_at_test: dict[str, str], learned: Sequence[str],
                 idx: Resamples, rmse_oracle: str) -> list[str]:
    """RMSE, the log-ratio table against the rule and the oracle, and the paired tables of each learned model."""
    rmse, gain = by_method(rows, "rmse"), by_method(rows, "log_ratio")
    auc, p20 = by_method(rows, "success_auc"), by_method(rows, "precision20")
    methods = list(rmse)
    oracle = rmse.get(rmse_oracle)
    body = [[m, *(fmt_ci(*ci(rmse[m], STATS[s], idx), digits=2) for s in ("mean", "median", "iqm"))] for m in methods]
    out = ["## RMSE (px), 95 % bootstrap CI", "", table(["method", "mean", "median", "IQM"], body), ""]

    header = ["method", "GT used at test", "log-ratio mean", "log-ratio median", "log-ratio IQM",
              "win rate vs rule", "regret vs oracle", "gap closed", "success AUC", "precision@20px"]
    body = []
    for m in methods:
        g = gain[m]
        win = ci(np.stack([rmse[m], rmse["rule"]]), _win, idx)
        row = [m, truth_at_test.get(m, "n"), *(fmt_ci(*ci(g, STATS[s], idx), signed=True) for s in ("mean", "median", "iqm")),
               fmt_ci(*win, digits=2)]
        if oracle is not None:
            row.append(fmt_ci(*ci(np.log(rmse[m] / oracle), STATS["mean"], idx)))
            og = gain[rmse_oracle]
            closed = ci(np.stack([g, og]), lambda x: x[..., 0, :].mean(-1) / x[..., 1, :].mean(-1), idx)
            row.append(fmt_ci(*closed, digits=2, signed=True) if og.mean() > 0 else "–")
        else:
            row += ["–", "–"]
        row += [f"{auc[m].mean():.4f}", f"{p20[m].mean():.4f}"]
        body.append(row)
    out += ["## Relative to the rule and the oracle", "", "log-ratio = log(RMSE_rule / RMSE) (> 0: better than the "
            f"rule); regret = mean log(RMSE / RMSE_{rmse_oracle}); gap closed = mean log-ratio / {rmse_oracle}'s mean "
            "log-ratio.", "", table(header, body), ""]

    for L in learned:
        body = []
        for m in methods:
            if m == L:
                continue
            d = ci(gain[L] - gain[m], STATS["mean"], idx)
            body.append([m, fmt_ci(*d, signed=True), f"{win_rate(rmse[L], rmse[m]):.2f}",
                         "yes" if d[1] > 0 or d[2] < 0 else "no"])
        out += [f"## Paired: {L} against each method", "", f"Δ = log(RMSE_method / RMSE_{L}) per episode (> 0: {L} better).",
                "", table(["method", "mean Δ [95 % CI]", f"P({L} better)", "CI excludes 0"], body), ""]
    return out


def _win(x: np.ndarray) -> np.ndarray:
    """Win rate of row 0 over row 1 along the last axis; ``x`` (..., 2, n)."""
    a, b = x[..., 0, :], x[..., 1, :]
    return np.mean((a < b) + 0.5 * (a == b), axis=-1)
