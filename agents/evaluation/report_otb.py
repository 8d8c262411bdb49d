"""Tables of ``summary.md`` for real-data sources (:mod:`bboxtune.agents.evaluation.report`): success AUC and
precision@20px against
``raw`` (the measurements) and ``rule`` with cluster-bootstrap CIs, their deltas per OTB attribute, and rows
per tracker for source "otb_tracker".

Δ AUC = success AUC_method − success AUC_reference per episode (> 0: the method is better), averaged over
episodes; precision@20px likewise. Per-attribute means are over the episodes of the sequences that carry the
attribute (OTB attributes.csv flags; analysis only, no CI: some attributes hold two or three sequences).
Per-tracker CIs resample that tracker's sequences.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from bboxtune.agents.evaluation.records import by_method, episode_column, table
from bboxtune.agents.evaluation.stats import STATS, Resamples, ci, cluster_bootstrap_indices, fmt_ci
from bboxtune.envs.data.otb import ATTRIBUTES

REFERENCES = ("raw", "rule")


def _delta(x: dict[str, np.ndarray], m: str, ref: str, idx: Resamples, keep: np.ndarray | None = None) -> str:
    a, b = (x[m], x[ref]) if keep is None else (x[m][keep], x[ref][keep])
    return fmt_ci(*ci(a - b, STATS["mean"], idx), digits=4, signed=True)


def auc_table(rows: Sequence[dict[str, Any]], idx: Resamples) -> list[str]:
    """Every method's success AUC and precision@20px, and their paired deltas against raw and rule."""
    auc, p20 = by_method(rows, "success_auc"), by_method(rows, "precision20")
    header = ["method", "success AUC", "Δ AUC vs raw", "Δ AUC vs rule", "precision@20px", "Δ precision vs raw"]
    body = [[m, fmt_ci(*ci(auc[m], STATS["mean"], idx), digits=4), _delta(auc, m, "raw", idx),
             _delta(auc, m, "rule", idx), fmt_ci(*ci(p20[m], STATS["mean"], idx), digits=4), _delta(p20, m, "raw", idx)]
            for m in auc]
    return ["## Success AUC and precision@20px against raw and the rule, 95 % bootstrap CI", "",
            "raw = the measurements themselves (no filter); Δ = method − reference per episode (> 0: method better).",
            "", table(header, body), ""]


def attribute_tables(rows: Sequence[dict[str, Any]], attributes: dict[str, frozenset[str]]) -> list[str]:
    """Mean Δ success AUC against raw and against rule over the episodes of each OTB attribute's sequences."""
    auc = by_method(rows, "success_auc")
    sequences = episode_column(rows, "sequence")
    flags = [attributes.get(s, frozenset()) for s in sequences]
    masks = {a: np.array([a in f for f in flags]) for a in ATTRIBUTES}
    header = ["method", *(f"{a} (n={len({s for s, f in zip(sequences, flags, strict=False) if a in f})})" for a in ATTRIBUTES)]
    out = []
    for ref in REFERENCES:
        body = [[m, *(f"{np.mean(auc[m][k] - auc[ref][k]):+.4f}" if k.any() else "–" for k in masks.values())]
                for m in auc if m != ref]
        out += [f"## Success AUC Δ vs {ref} by OTB attribute (analysis only)", "",
                f"Mean over the episodes of the sequences with the attribute (n = sequences); > 0: better than {ref}.",
                "", table(header, body), ""]
    return out


def tracker_table(rows: Sequence[dict[str, Any]], learned: Sequence[str], n_boot: int, seed: int) -> list[str]:
    """Per tracker: success AUC and precision@20px of raw, rule, each learned model and the oracles, with the
    paired deltas against raw (CIs resample that tracker's sequences)."""
    auc, p20 = by_method(rows, "success_auc"), by_method(rows, "precision20")
    trackers, sequences = episode_column(rows, "tracker"), episode_column(rows, "sequence")
    shown = [m for m in auc if m in REFERENCES or m in learned or m.startswith("oracle")]
    header = ["tracker", "method", "success AUC", "precision@20px", "Δ AUC vs raw [95 % CI]",
              "Δ precision vs raw [95 % CI]"]
    body = []
    for tracker in sorted(set(trackers) - {""}):  # "": episodes of a "mix" that are not tracker output
        keep = np.array([t == tracker for t in trackers])
        idx = cluster_bootstrap_indices([s for s, k in zip(sequences, keep, strict=False) if k], n_boot, seed)
        body += [[tracker, m, f"{auc[m][keep].mean():.4f}", f"{p20[m][keep].mean():.4f}",
                  _delta(auc, m, "raw", idx, keep), _delta(p20, m, "raw", idx, keep)] for m in shown]
    return ["## Per tracker: success AUC and precision@20px", "",
            "Episodes of each tracker (one per sequence it has output for); CIs resample its sequences.", "",
            table(header, body), ""]
