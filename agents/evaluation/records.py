"""Per-episode records of ``scripts/compare.py`` (one dict per method × episode) read by column, and markdown
tables."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


def by_method(rows: Sequence[dict[str, Any]], key: str) -> dict[str, np.ndarray]:
    """method -> values of ``key`` ordered by episode (NaN where a record has no ``key``: e.g. the true ψ of a
    tracker-output episode in a "mix" evaluation)."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    return {m: np.array([r.get(key, np.nan) for r in sorted((r for r in rows if r["method"] == m), key=lambda r: r["episode"])],
                        dtype=float) for m in methods}


def episode_column(rows: Sequence[dict[str, Any]], key: str) -> list[Any]:
    """The value of ``key`` for each episode, ordered by episode (read from the ``rule`` rows; "" if absent)."""
    return [r.get(key, "") for r in sorted((r for r in rows if r["method"] == "rule"), key=lambda r: r["episode"])]


def table(header: Sequence[str], body: Sequence[Sequence[str]]) -> str:
    """A markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return "\n".join(lines)
