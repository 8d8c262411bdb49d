"""The interface every back end shares: ``Filter(model, **params).run(y) -> states``.

A back end subclasses :class:`Filter`, lists its parameters with their defaults in ``DEFAULTS`` and
implements ``_run_axes`` on one batch of independent two-state coordinate problems (every coordinate of
every track is one "channel"). ``run`` validates ``y``, broadcasts scalar / per-track (B,) parameters,
splits boxes into channels and assembles the (B, T, K) state array (positions first, then velocities).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from filters.model import StateSpaceModel
from filters.validation import broadcast_params, check_measurements


class Filter(ABC):
    """A configured filter. Construct with :func:`filters.make`; call :meth:`run` on measurements.

    ``params`` holds the validated parameters, each a float/int array of shape () or (B,).
    """

    name: ClassVar[str]
    DEFAULTS: ClassVar[dict[str, Any]]  # every accepted parameter and its default
    PER_TRACK: ClassVar[tuple[str, ...]]  # parameters that may be scalars or (B,) arrays, one per track

    def __init__(self, model: StateSpaceModel, **params: Any) -> None:
        unknown = sorted(set(params) - set(self.DEFAULTS))
        if unknown:
            raise ValueError(
                f"{self.name}: unknown parameter(s) {unknown}; allowed: {sorted(self.DEFAULTS)}"
            )
        self.model = model
        self.params = self._validate({**self.DEFAULTS, **params})

    @abstractmethod
    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        """Check every parameter (ValueError naming it, its value and the allowed range)."""

    @abstractmethod
    def _run_axes(self, z: np.ndarray, params: dict[str, Any]) -> np.ndarray:
        """Filter channels ``z`` (C, T) of one coordinate each (channel c = track c // M, coordinate
        c % M); the ``PER_TRACK`` parameters arrive as arrays (C,), the others as validated.

        Returns posterior two-state estimates (C, T, 2) = [position, velocity] at every frame."""

    def run(self, y: np.ndarray) -> np.ndarray:
        """Filter ``y`` shaped (T, M) or (B, T, M); NaN = missing. Returns states (T, K) or (B, T, K)."""
        Y, batched = check_measurements(y, self.model.M)
        n_tracks, T, M = Y.shape
        per_track = {k: v for k, v in self.params.items() if k in self.PER_TRACK}
        per_track = broadcast_params(per_track, n_tracks, batched)
        per_channel = {k: np.repeat(v, M) for k, v in per_track.items()}
        fixed = {k: v for k, v in self.params.items() if k not in per_channel}
        z = Y.transpose(0, 2, 1).reshape(n_tracks * M, T)
        axes = self._run_axes(z, {**fixed, **per_channel})
        states = merge_axes(axes, n_tracks, M)
        return states if batched else states[0]


def merge_axes(axes: np.ndarray, n_tracks: int, M: int) -> np.ndarray:
    """(B·M, T, 2) per-coordinate [p, v] → (B, T, 2M) with positions first, then velocities."""
    T = axes.shape[1]
    per = axes.reshape(n_tracks, M, T, 2)
    return np.concatenate([per[..., 0], per[..., 1]], axis=1).transpose(0, 2, 1)


def split_state(vec: np.ndarray, M: int) -> np.ndarray:
    """A full-model state vector (K,) → per-coordinate [p, v] pairs (M, 2)."""
    vec = np.asarray(vec, dtype=float)
    return np.stack([vec[:M], vec[M:]], axis=-1)


def split_covariance(P: np.ndarray, M: int, name: str = "P0") -> np.ndarray:
    """A full-model covariance (K, K) → per-coordinate 2×2 blocks (M, 2, 2).

    The coordinates are filtered independently, so ``P`` must not couple them: every entry linking two
    different coordinates must be zero (ValueError otherwise)."""
    P = np.asarray(P, dtype=float)
    idx = np.arange(M)
    blocks = np.empty((M, 2, 2))
    for a in range(2):
        for b in range(2):
            blocks[:, a, b] = P[a * M + idx, b * M + idx]
    rebuilt = np.zeros_like(P)
    for a in range(2):
        for b in range(2):
            rebuilt[a * M + idx, b * M + idx] = blocks[:, a, b]
    if not np.array_equal(rebuilt, P):
        raise ValueError(f"{name} couples different coordinates; allowed: a covariance that is block-diagonal per coordinate")
    return blocks
