"""State-space models for box coordinates (backward-Euler convention of seeds 000–004).

    x_n = F x_{n-1} + B w_n,      w_n ~ N(0, σ_w² I)   (white acceleration, one per coordinate)
    y_n = H x_n + v_n                                  (v_n white, or Gauss–Markov coloured)

State layout: positions first, then velocities, ``x = [p_1 … p_d, v_1 … v_d]`` (d = ``ndim``), so the
positions of a filtered state array are ``states[..., :model.M]``. For ``ndim = 1`` this is the papers'
two-state ``[p, v]`` model. Coordinates are independent (block-diagonal F, B, H), which the filters use to
run every coordinate of every track as one batch of two-state problems.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from bboxtune.filters.validation import check_tau, short_repr


@dataclass(frozen=True, eq=False)
class StateSpaceModel:
    """A linear time-invariant model ``x_n = F x_{n-1} + B w_n``, ``y_n = H x_n + v_n``."""

    F: np.ndarray  # (K, K) state transition
    H: np.ndarray  # (M, K) observation matrix
    B: np.ndarray  # (K, M) noise input: white acceleration [τ²/2, τ]ᵀ per coordinate
    tau: float  # s, sampling interval
    ndim: int  # number of independent coordinates d (1 scalar, 2 centroid, 4 box cx, cy, w, h)

    @property
    def K(self) -> int:
        """State size (2·ndim)."""
        return self.F.shape[0]

    @property
    def M(self) -> int:
        """Measurement size (ndim)."""
        return self.H.shape[0]

    @cached_property
    def _axis(self) -> StateSpaceModel:
        return constant_velocity(self.tau, ndim=1)

    def axis(self) -> StateSpaceModel:
        """The one-coordinate two-state model every coordinate of this model follows."""
        return self if self.ndim == 1 else self._axis


def constant_velocity(tau: float, ndim: int = 1) -> StateSpaceModel:
    """Constant-velocity model with white acceleration noise for ``ndim`` independent coordinates; ``tau`` (s)
    within :data:`bboxtune.filters.validation.TAU_RANGE`.

    Per coordinate: ``F = [[1, τ], [0, 1]]``, ``H = [1, 0]``, ``B = [τ²/2, τ]ᵀ``, so the process noise
    covariance is ``Q = σ_w² B Bᵀ`` with σ_w the acceleration noise std (units per s²).

    >>> m = constant_velocity(0.05, ndim=4)
    >>> m.K, m.M, m.F.shape, m.B.shape
    (8, 4, (8, 8), (8, 4))
    """
    tau = float(check_tau(tau))
    if not isinstance(ndim, (int, np.integer)) or isinstance(ndim, bool) or ndim < 1:
        raise ValueError(f"ndim={ndim!r} must be an integer >= 1")
    return _constant_velocity(tau, int(ndim))


def check_model(model: object) -> StateSpaceModel:
    """``model`` if it is a :class:`StateSpaceModel`; a TypeError naming ``model`` and the expected type otherwise."""
    if not isinstance(model, StateSpaceModel):
        raise TypeError(f"model={short_repr(model)} ({type(model).__name__}); allowed: a StateSpaceModel, e.g. "
                        "bboxtune.filters.constant_velocity(tau, ndim)")
    return model


@lru_cache(maxsize=1024)
def _constant_velocity(tau: float, ndim: int) -> StateSpaceModel:
    """Built once per (τ, ndim): the models are immutable (read-only arrays, frozen dataclass)."""
    K = 2 * ndim
    idx = np.arange(ndim)
    F = np.eye(K)
    F[idx, ndim + idx] = tau
    H = np.eye(ndim, K)
    B = np.zeros((K, ndim))
    B[idx, idx] = 0.5 * tau**2
    B[ndim + idx, idx] = tau
    for a in (F, H, B):
        a.setflags(write=False)
    return StateSpaceModel(F=F, H=H, B=B, tau=tau, ndim=ndim)


def matrix_powers(A: np.ndarray, n: int) -> np.ndarray:
    """``[A⁰, A¹, …, A^{n−1}]`` stacked (n, K, K), by doubling (about log₂ n stacked products)."""
    powers = np.eye(A.shape[0])[None]
    step = np.asarray(A, dtype=float)
    while powers.shape[0] < n:
        powers = np.concatenate([powers, powers @ step])
        step = step @ step
    return powers[:n]
