"""Full-model states and covariances (positions first, then velocities: K = 2 M) and their per-coordinate [p, v]
blocks: every back end filters each coordinate as its own two-state problem, so a covariance may not couple two
coordinates."""

from __future__ import annotations

import numpy as np


def block_diagonal(blocks: np.ndarray) -> np.ndarray:
    """Per-coordinate 2×2 blocks (B, M, 2, 2) → full-model covariances (B, K, K) (positions first)."""
    n_tracks, M = blocks.shape[:2]
    P = np.zeros((n_tracks, 2, M, 2, M))
    idx = np.arange(M)
    P[:, :, idx, :, idx] = blocks.transpose(1, 0, 2, 3)  # advanced indices first: (M, B, 2, 2)
    return P.reshape(n_tracks, 2 * M, 2 * M)


def split_state(vec: np.ndarray, M: int) -> np.ndarray:
    """A full-model state vector (K,) → per-coordinate [p, v] pairs (M, 2)."""
    vec = np.asarray(vec, dtype=float)
    return np.stack([vec[:M], vec[M:]], axis=-1)


def split_covariance(P: np.ndarray, M: int, name: str = "P0") -> np.ndarray:
    """A full-model covariance (K, K) → per-coordinate 2×2 blocks (M, 2, 2).

    The coordinates are filtered independently, so ``P`` must not couple them: every entry linking two
    different coordinates must be zero (ValueError otherwise)."""
    return coordinate_blocks(np.asarray(P, dtype=float)[None], M, name)[0]


def coordinate_blocks(P: np.ndarray, M: int, name: str) -> np.ndarray:
    """Full-model covariances (B, K, K) → per-coordinate 2×2 blocks (B, M, 2, 2); ValueError naming ``name``
    if an entry linking two different coordinates is not zero (NaN blocks allowed)."""
    blocks = np.diagonal(P.reshape(len(P), 2, M, 2, M), axis1=2, axis2=4).transpose(0, 3, 1, 2)
    if not np.array_equal(block_diagonal(blocks), P, equal_nan=True):
        raise ValueError(f"{name} couples different coordinates; allowed: a covariance that is block-diagonal "
                         "per coordinate")
    return blocks
