"""assign: SORT's matching rule (one-to-one pairs above the threshold as they are, else the Hungarian assignment)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from bboxtune.agents.tracking.association import assign


def _reference(overlap: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rule as counts per row and column of the pairs above the threshold (the module docstring's words)."""
    n, m = overlap.shape
    pairs = np.empty((0, 2), dtype=np.int64)
    if n and m:
        above = overlap > threshold
        if above.sum(axis=0).max() <= 1 and above.sum(axis=1).max() <= 1:
            rows, cols = np.nonzero(above)
        else:
            rows, cols = linear_sum_assignment(overlap, maximize=True)
        keep = overlap[rows, cols] >= threshold
        pairs = np.stack([rows[keep], cols[keep]], axis=1).astype(np.int64)
    return pairs, np.setdiff1d(np.arange(n), pairs[:, 0]), np.setdiff1d(np.arange(m), pairs[:, 1])


def test_assign_equals_the_rule_on_random_overlaps() -> None:
    rng = np.random.default_rng(7)
    hungarian = 0
    for _ in range(3000):
        n, m = rng.integers(0, 7, 2)
        threshold = float(rng.choice([0.2, 0.3, 0.5]))
        overlap = rng.random((n, m)) * (rng.random((n, m)) < 0.35)
        overlap[rng.random((n, m)) < 0.05] = threshold  # ties at the threshold: kept by Hungarian, not taken as above
        got, want = assign(overlap, threshold), _reference(overlap, threshold)
        for g, w in zip(got, want, strict=True):
            assert g.dtype == np.int64 and g.tolist() == w.tolist()
        above = overlap > threshold
        hungarian += bool(n and m and max(above.sum(axis=0).max(), above.sum(axis=1).max()) > 1)
    assert hungarian > 300  # both branches ran
