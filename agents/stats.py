"""Paired statistics over test episodes: IQM, percentile-bootstrap confidence intervals, win rates.

All methods are scored on the same episodes (common random numbers), so comparisons are paired: a
bootstrap resample draws episode indices once and applies them to every method.

>>> import numpy as np
>>> round(iqm(np.arange(8.0)), 6)   # mean of the middle half: 2, 3, 4, 5
3.5
>>> round(win_rate(np.array([1.0, 2.0, 3.0]), np.array([2.0, 2.0, 2.0])), 4)  # 1 win, 1 tie, 1 loss
0.5
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.stats import trim_mean

Stat = Callable[[np.ndarray], np.ndarray]  # (..., n) -> (...)


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
    "iqm": lambda x: iqm(x, axis=-1),
}


def bootstrap_indices(n: int, n_boot: int, seed: int) -> np.ndarray:
    """(n_boot, n) episode indices drawn with replacement (the same draws for every method: paired)."""
    if n < 1 or n_boot < 1:
        raise ValueError(f"n={n}, n_boot={n_boot}; allowed: both >= 1")
    return np.random.default_rng(seed).integers(n, size=(n_boot, n))


def ci(x: np.ndarray, stat: Stat, idx: np.ndarray, level: float = 0.95) -> tuple[float, float, float]:
    """(estimate, low, high): ``stat`` of ``x`` and its percentile-bootstrap interval over the resamples
    ``idx`` (n_boot, n). ``x`` is (n,) or (k, n) (k paired series, resampled together); ``stat`` maps
    (..., n) resp. (..., k, n) to (...).

    >>> idx = bootstrap_indices(4, 100, seed=0)
    >>> est, lo, hi = ci(np.array([1.0, 2.0, 3.0, 4.0]), STATS["mean"], idx)
    >>> est, 1.0 <= lo <= est <= hi <= 4.0
    (2.5, True)
    """
    x = np.asarray(x, dtype=np.float64)
    boots = stat(np.moveaxis(x[..., idx], -2, 0) if x.ndim == 2 else x[idx])
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(boots, [alpha, 1.0 - alpha])
    return float(stat(x[None])[0]), float(lo), float(hi)


def fmt_ci(est: float, lo: float, hi: float, digits: int = 3, signed: bool = False) -> str:
    """``est [lo, hi]``; ``signed``: every number with its sign (for differences and log-ratios)."""
    f = f"+.{digits}f" if signed else f".{digits}f"
    return f"{est:{f}} [{lo:{f}}, {hi:{f}}]"
