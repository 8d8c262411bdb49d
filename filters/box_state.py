"""The state arrays of the box Kalman filters (:class:`bboxtune.filters.bytetrack_kf.BoxKF`) and their noise,
affine in the box height: the predict / update / initiate steps shared by the batch recursion, the online engine
(:mod:`bboxtune.filters.box_online`) and the tracker's search (:mod:`bboxtune.agents.tracking.search_tune`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# The state of n tracks is one array X (5, 4, n): per coordinate and track the mean [p, v] (v per frame) and the
# covariance block [[P00, P01], [P01, P11]], in the order [p, v, P01, P00, P11] so that the paired steps of the
# recursion are single slices; NaN for a track without a detection yet.
_P, _V, _P01, _P00, _P11 = range(5)


@dataclass(frozen=True)
class HeightNoise:
    """The standard deviations of a :class:`BoxKF`, per coordinate and track, each affine in the height h:
    std = slope · h + offset, as (slope, offset) pairs; ``start`` and ``process`` broadcast to (2, 4, n) (the
    coordinates, then their rates), ``measurement`` to (4, n)."""

    start: tuple[np.ndarray, np.ndarray]  # P₀, h = the first detection's height
    process: tuple[np.ndarray, np.ndarray]  # Q, h = the current mean height
    measurement: tuple[np.ndarray, np.ndarray]  # R, h = the predicted height


class HeightVariance:
    """The variance (slope · h + offset)² of one :class:`HeightNoise` pair, shaped (…, 4, n): computed once if the
    slope is 0."""

    def __init__(self, pair: tuple[np.ndarray, np.ndarray], shape: tuple[int, ...]) -> None:
        self.slope, self.offset = (np.broadcast_to(a, shape) for a in pair)
        self.fixed = None if self.slope.any() else np.square(self.offset)

    @property
    def pair(self) -> tuple[np.ndarray, np.ndarray]:
        """(slope, offset), each of the full shape."""
        return self.slope, self.offset

    @classmethod
    def of_full(cls, slope: np.ndarray, offset: np.ndarray) -> HeightVariance:
        """The variance of a (slope, offset) pair already of the full shape (…, 4, n), as the arrays (views kept, not
        copied): what ``HeightVariance((slope, offset), slope.shape)`` computes, without its broadcasting."""
        out = cls.__new__(cls)
        out.slope, out.offset = slope, offset
        out.fixed = None if np.count_nonzero(slope) else np.square(offset)  # as slope.any(), faster
        return out

    def at(self, h: np.ndarray, rows: slice | np.ndarray = slice(None)) -> np.ndarray:
        """At heights h (n,) (or of the tracks ``rows`` only)."""
        if self.fixed is not None:
            return self.fixed[..., rows]
        return np.square(self.slope[..., rows] * h + self.offset[..., rows])


def update_state(X: np.ndarray, z: np.ndarray, R: HeightVariance, gate: np.ndarray | None) -> None:
    """The update step on state X (5, 4, n) with measured coordinates z (4, n), in place (h: the predicted height):
    S = H P Hᵀ + R, K = P Hᵀ S⁻¹ = [K0, K1], P ← P − K S Kᵀ; ``gate`` (n,) 0 where a track has no detection (its
    z is 0 there: predict only), None when every track has one."""
    K = X[_P01:_P00 + 1] / (X[_P00] + R.at(X[_P, 3]))  # [K1, K0]
    if gate is not None:
        K *= gate
    X[_P:_V + 1] += K[::-1] * (z - X[_P])
    X[_P11] -= K[0] * X[_P01]
    X[_P01:_P00 + 1] -= K[1] * X[_P01:_P00 + 1]  # P01, P00 times (1 − K0)


def initiate(X: np.ndarray, m: np.ndarray, P_start: HeightVariance, rows: np.ndarray) -> None:
    """Start the tracks ``rows`` of state X (5, 4, n) at their first measured coordinates m (4, len(rows)), in place:
    mean [m, 0], P₀ from the detection's height."""
    X[_P][:, rows], X[_V][:, rows], X[_P01][:, rows] = m, 0.0, 0.0
    X[_P00:][..., rows] = P_start.at(m[3], rows)
