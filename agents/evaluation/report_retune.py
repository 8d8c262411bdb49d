"""The FilterRetune-v0 part of a comparison's summary: how much of the one-shot → per-window gap a method closes.

gap closed (sequential) = mean_e (g_m,e − g_oneshot_oracle,e) / mean_e (g_window_oracle,e − g_oneshot_oracle,e),
g = log(RMSE_rule / RMSE): 0 = as good as the best single action for the track, 1 = as good as the greedy
per-window oracle. Same paired cluster bootstrap as the rest of the summary (bboxtune.agents.evaluation.report).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from bboxtune.agents.evaluation.records import by_method, table
from bboxtune.agents.evaluation.report import clusters
from bboxtune.agents.evaluation.retune_eval import ONESHOT_LEARNED, ONESHOT_LEARNED_ONLINE, ONESHOT_ORACLE, WINDOW_ORACLE
from bboxtune.agents.evaluation.stats import STATS, ci, cluster_bootstrap_indices, fmt_ci


def retune_tables(rows: Sequence[dict[str, Any]], learned: Sequence[str], n_boot: int = 2000, seed: int = 0) -> list[str]:
    """Markdown lines: the gap-closed table and each learned method's paired log-ratio against ``oneshot_learned``
    (when it was scored)."""
    gain = by_method(rows, "log_ratio")
    if ONESHOT_ORACLE not in gain or WINDOW_ORACLE not in gain:
        return []
    idx = cluster_bootstrap_indices(clusters(rows), n_boot, seed)
    lo, hi = gain[ONESHOT_ORACLE], gain[WINDOW_ORACLE]

    def closed(x: np.ndarray) -> np.ndarray:
        g, a, b = x[..., 0, :], x[..., 1, :], x[..., 2, :]
        return (g - a).mean(-1) / (b - a).mean(-1)

    body = [[m, fmt_ci(*ci(g, STATS["mean"], idx), signed=True), fmt_ci(*ci(np.stack([g, lo, hi]), closed, idx), digits=2,
                                                                        signed=True)] for m, g in gain.items()]
    out = ["## Re-tuning: the one-shot → per-window gap", "",
           f"gap closed = mean (g − g_{ONESHOT_ORACLE}) / mean (g_{WINDOW_ORACLE} − g_{ONESHOT_ORACLE}), g = log(RMSE_rule / "
           f"RMSE): 0 = the best single action per track (with the truth), 1 = the greedy per-window oracle. Gap: "
           f"{(hi - lo).mean():+.3f} in mean log-ratio.", "",
           table(["method", "log-ratio vs rule [95 % CI]", "gap closed [95 % CI]"], body), ""]
    for ref in (ONESHOT_LEARNED, ONESHOT_LEARNED_ONLINE):
        if ref in gain:
            body = [[m, fmt_ci(*ci(gain[m] - gain[ref], STATS["mean"], idx), signed=True)] for m in learned]
            out += [f"## Paired: sequential against {ref}", "",
                    f"Δ = log(RMSE_{ref} / RMSE_method) per episode (> 0: re-tuning better).", "",
                    table(["method", "mean Δ [95 % CI]"], body), ""]
    return out
