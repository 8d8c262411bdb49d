"""Paired statistics over test episodes: IQM, percentile-bootstrap confidence intervals, win rates.

All methods are scored on the same episodes (common random numbers), so comparisons are paired: a
bootstrap resample draws episode indices once and applies them to every method.

Episodes that share a source of variation (the OTB episodes of one sequence: its motion, its tracker's
failures) are not independent, so :func:`cluster_bootstrap_indices` resamples *clusters* (e.g. sequences) with
replacement and takes all episodes of every drawn cluster; with every episode its own cluster it draws exactly
:func:`bootstrap_indices`. A resample set (:data:`Resamples`) is an (n_boot, m) index array when every resample
has the same size m, else a list of n_boot index arrays; :func:`ci` takes either.

>>> import numpy as np
>>> round(iqm(np.arange(8.0)), 6)   # mean of the middle half: 2, 3, 4, 5
3.5
>>> round(win_rate(np.array([1.0, 2.0, 3.0]), np.array([2.0, 2.0, 2.0])), 4)  # 1 win, 1 tie, 1 loss
0.5
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import cast

import numpy as np
from scipy.stats import trim_mean

Stat = Callable[[np.ndarray], np.ndarray]  # (..., n) -> (...)
Resamples = np.ndarray | list[np.ndarray]  # (n_boot, m) episode indices, or n_boot index arrays of varying size


def iqm(x: np.ndarray, axis: int = -1) -> np.ndarray | float:
    """Interquartile mean: the mean of the values between the 25th and 75th percentiles (25 % trimmed mean)."""
    out = trim_mean(x, 0.25, axis=axis)
    return float(out) if np.ndim(out) == 0 else out


def win_rate(rmse: np.ndarray, reference: np.ndarray) -> float:
    """Probability of improvement: fraction of episodes with lower RMSE than ``reference``, ties count half."""
    return float(np.mean((rmse < reference) + 0.5 * (rmse == reference)))


STATS: dict[str, Stat] = {
    "mean": lambda x: np.mean(x, axis=-1),
    "median": lambda x: np.median(x, axis=-1),
    "iqm": lambda x: cast(np.ndarray, iqm(x, axis=-1)),  # iqm's float case is a 1-D x only
}


def resample_indices(n: int, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """(n_boot, n) indices drawn with replacement from ``rng``: ``rng.integers(n, size=(n_boot, n))``."""
    if n < 1 or n_boot < 1:
        raise ValueError(f"n={n}, n_boot={n_boot}; allowed: both >= 1")
    return rng.integers(n, size=(n_boot, n))


def bootstrap_indices(n: int, n_boot: int, seed: int) -> np.ndarray:
    """(n_boot, n) episode indices drawn with replacement (the same draws for every method: paired):
    :func:`resample_indices` from ``default_rng(seed)``."""
    return resample_indices(n, n_boot, np.random.default_rng(seed))


def cluster_bootstrap_indices(clusters: Sequence[Hashable], n_boot: int, seed: int) -> Resamples:
    """Resamples of the episodes whose cluster labels are ``clusters`` (one per episode): each draws the
    C distinct clusters C times with replacement (the same draws for every method: paired) and takes all
    episodes of each drawn cluster, in episode order within a cluster. Clusters are numbered in order of
    first appearance; the draws are ``default_rng(seed).integers(C, size=(n_boot, C))``, so labels that are
    all distinct give :func:`bootstrap_indices` ``(n, n_boot, seed)`` exactly. An (n_boot, m) array when all
    clusters have the same size, else a list of n_boot arrays.

    >>> cluster_bootstrap_indices(["a", "a", "b", "b"], 3, seed=0).shape  # 2 clusters of 2 episodes
    (3, 4)
    """
    labels = list(clusters)
    if not labels or n_boot < 1:
        raise ValueError(f"{len(labels)} episodes, n_boot={n_boot}; allowed: both >= 1")
    members: dict[Hashable, list[int]] = {}
    for i, label in enumerate(labels):
        members.setdefault(label, []).append(i)
    groups = [np.array(m, dtype=np.intp) for m in members.values()]
    draws = bootstrap_indices(len(groups), n_boot, seed)
    if len({len(g) for g in groups}) == 1:
        return np.stack(groups)[draws].reshape(n_boot, -1)
    return [np.concatenate([groups[c] for c in row]) for row in draws]


def n_clusters(clusters: Sequence[Hashable]) -> int:
    """How many distinct clusters the labels ``clusters`` name."""
    return len(set(clusters))


def ci(x: np.ndarray, stat: Stat, idx: Resamples, level: float = 0.95) -> tuple[float, float, float]:
    """(estimate, low, high): ``stat`` of ``x`` and its percentile-bootstrap interval over the resamples
    ``idx`` (:data:`Resamples` of the n episodes). ``x`` is (n,) or (k, n) (k paired series, resampled together);
    ``stat`` maps (..., n) resp. (..., k, n) to (...).

    >>> idx = bootstrap_indices(4, 100, seed=0)
    >>> est, lo, hi = ci(np.array([1.0, 2.0, 3.0, 4.0]), STATS["mean"], idx)
    >>> est, 1.0 <= lo <= est <= hi <= 4.0
    (2.5, True)
    """
    x = np.asarray(x, dtype=np.float64)
    if isinstance(idx, list):  # resamples of varying size: one stat call each
        boots = np.array([stat(x[..., i]) for i in idx])
    else:
        boots = stat(np.moveaxis(x[..., idx], -2, 0) if x.ndim == 2 else x[idx])
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(boots, [alpha, 1.0 - alpha])
    return float(stat(x[None])[0]), float(lo), float(hi)


def paired_mean_ci(diff: np.ndarray, rng: np.random.Generator, n_boot: int = 2000) -> tuple[float, float]:
    """95 % percentile-bootstrap interval (``np.percentile`` at 2.5 and 97.5) of the mean of the paired
    differences ``diff`` (n,), over :func:`resample_indices` drawn from ``rng``. ``rng`` advances, so successive
    calls with one generator (the video tables: one per run, seeded by ``--seed``) draw successive resamples."""
    diff = np.asarray(diff, dtype=float)
    means = STATS["mean"](diff[resample_indices(len(diff), n_boot, rng)])
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)


def fmt_ci(est: float, lo: float, hi: float, digits: int = 3, signed: bool = False) -> str:
    """``est [lo, hi]``; ``signed``: every number with its sign (for differences and log-ratios)."""
    f = f"+.{digits}f" if signed else f".{digits}f"
    return f"{est:{f}} [{lo:{f}}, {hi:{f}}]"
