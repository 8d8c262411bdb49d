"""The gap policy of :class:`bboxtune.filters.bytetrack_kf.ByteTrackKF`: what it outputs inside a detection gap.

Inside a gap (a frame after a track's first detection without one) the box Kalman filter predicts: its mean moves
on at the velocity estimated at the last detection, for the centre (x, y) and for the size (a, h) alike. The gap
policy changes the *output* only: from the last detected frame's estimate [p, v] (per coordinate, v per frame) the
output follows the damped constant-velocity model

    v_k = d v_{k-1},   p_k = p_{k-1} + v_k   (k = 1, 2, … frames into the gap),

with d = ρ^τ per frame for a decay ρ per second of gap (τ the frame interval in s), so that a setting transfers
across frame rates: ``gap_velocity_decay`` ρ for x, y, ``gap_size_decay`` for a, h (each in [0, 1]; 1: the
filter's own prediction, bit for bit, 0: the coordinate held at its last detected estimate). The filter's state,
and so every estimate on a detected frame, is unchanged.

The output state O (2, 4, n) = [p, v] runs beside the filter's state X (:mod:`bboxtune.filters.bytetrack_kf`): set to
X's [p, v] on every detected frame, stepped by :func:`step` on the others. A run continued from a carry
(``run_from``) starts O from X and the frames since the last detection (``Carry.missed``) in closed form
(:func:`start`), equal to the step-by-step output to round-off.
"""

from __future__ import annotations

import numpy as np

# the filter coordinates (x, y, a, h) whose rate each decay damps
CENTRE = np.array([1.0, 1.0, 0.0, 0.0])
SIZE = 1.0 - CENTRE


def frame_decay(velocity: np.ndarray, size: np.ndarray, tau: float) -> np.ndarray:
    """The per-frame factors d (4, n) of the decays per second ``velocity``, ``size`` (each (n,)) at frame interval
    ``tau`` (s): ρ^τ (0 stays 0, 1 stays 1)."""
    return CENTRE[:, None] * velocity ** tau + SIZE[:, None] * size ** tau


def start(X: np.ndarray, missed: np.ndarray, decay: np.ndarray) -> np.ndarray:
    """The output state O (2, 4, n) of tracks in state X (5, 4, n) (rows [p, v] first) that are ``missed`` (n,)
    frames into a gap (0: at a detection), with per-frame factors ``decay`` (4, n): the filter predicted
    p = p₀ + g v₀ and kept v = v₀, the policy outputs p₀ + v₀ S(g), v₀ dᵍ with S(g) = d + d² + … + dᵍ."""
    g = missed[None].astype(float)
    power = decay**g
    with np.errstate(divide="ignore", invalid="ignore"):
        S = np.where(decay == 1.0, g, decay * (1.0 - power) / (1.0 - decay))
    p, v = X[0], X[1]
    return np.stack([p - v * (g - S), v * power])


def step(O: np.ndarray, X: np.ndarray, detected: np.ndarray, decay: np.ndarray) -> None:
    """One frame of the output state O (2, 4, n) in place, after the filter's step to X (5, 4, n): X's [p, v]
    where ``detected`` (n,), else v ← d v, p ← p + v."""
    O[1] *= decay
    O[0] += O[1]
    O[:, :, detected] = X[:2, :, detected]


def missed_after(detected: np.ndarray, before: np.ndarray, started: np.ndarray) -> np.ndarray:
    """Frames since the last detection (n,) after a run of ``detected`` (T, n) frames that continued tracks
    ``before`` (n,) frames into a gap; 0 for tracks not ``started`` (n,)."""
    T = len(detected)
    seen = detected.any(axis=0)
    last = T - 1 - np.argmax(detected[::-1], axis=0)
    return np.where(started, np.where(seen, T - 1 - last, before + T), 0).astype(float)
