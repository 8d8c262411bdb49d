"""The "otb" motion model of the simulator: box motion fitted to OTB-100's ground truth (docs/otb_motion.md).

Per box (time in s, h = τ + δ the truth's frame step; n = 0 … T − 1):

* Centre velocity, per axis, in box scales per second (scale s_n = √(w_n h_n) of the true box):
  r_n = μ_n + j_n. The *cruise* velocity μ is piecewise constant: at frame 0 and, for n >= 1, with
  probability 1 − exp(−λ h) at each frame (a manoeuvre, Poisson at rate λ = ``switch_rate``) it is redrawn
  from N(0, σ_c²). The *jitter* j is a stationary AR(1) (a sampled Ornstein–Uhlenbeck velocity):
  j_n = φ j_{n−1} + √(1 − φ²) σ_j ε_n, φ = exp(−h / ``jitter_time``). The episode's velocity level
  σ_r (rms of r) splits as σ_c² = c σ_r², σ_j² = (1 − c) σ_r² with c = ``cruise_share``.
* Centre: c_n = c_{n−1} + h s_{n−1} r_{n−1} (px), true velocity s_n r_n (px/s).
* Sizes: ℓ = log(w / w_0) (and h) is a random walk, ℓ_n = ℓ_{n−1} + σ_ℓ √h ε_n, reflected at the size
  bounds like the "cv" model's; the true size velocity is w_n (ℓ_n − ℓ_{n−1}) / h (0 at frame 0).
* Per episode, σ_r and σ_ℓ are log-normal: log σ_r ~ N(``level_log_mean``, ``level_log_std``²), log σ_ℓ ~
  N(``size_log_mean``, ``size_log_std``²) (OTB's sequences differ by more than a decade in motion).

The process starts in its stationary law (x0 gives the first box; its velocities are not used). Random draws,
in the "cv" model's order and shapes first: ε of the jitter and the sizes (B, T − 1, 4), the CMN ξ (B, T, M);
then the jitter start and the cruise values (B, T + 1, 2) and the switch uniforms (B, T, 2). The arithmetic of a
track does not depend on the batch it is drawn in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter


@dataclass(frozen=True)
class OTBMotion:
    """Fitted parameters (``scripts/otb_motion.py`` on the OTB-100 train split; docs/otb_motion.json)."""

    switch_rate: float  # λ, 1/s: manoeuvres (redraws of the cruise velocity) per second
    cruise_share: float  # c: share of the velocity variance in the cruise component, in [0, 1]
    jitter_time: float  # s: correlation time of the jitter velocity
    level_log_mean: float  # mean of log σ_r, σ_r = rms centre velocity in box scales per second
    level_log_std: float  # std of log σ_r across episodes
    size_log_mean: float  # mean of log σ_ℓ, σ_ℓ = log-size random-walk std in 1/√s
    size_log_std: float  # std of log σ_ℓ across episodes

    def __post_init__(self) -> None:
        for name in ("switch_rate", "jitter_time", "level_log_std", "size_log_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r} is out of range: allowed finite values > 0")
        if not 0.0 <= self.cruise_share <= 1.0:
            raise ValueError(f"cruise_share={self.cruise_share!r} is out of range: allowed [0, 1]")
        for name in ("level_log_mean", "size_log_mean"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name}={getattr(self, name)!r} must be finite")

    def sample_levels(self, rng: np.random.Generator) -> tuple[float, float]:
        """One episode's (σ_r in box scales/s, σ_ℓ in 1/√s)."""
        level = math.exp(rng.normal(self.level_log_mean, self.level_log_std))
        return level, math.exp(rng.normal(self.size_log_mean, self.size_log_std))


# Fitted on the 55 OTB-100 train sequences at 30 frames/s (docs/otb_motion.md, scripts/otb_motion.py).
OTB_MOTION = OTBMotion(switch_rate=3.05, cruise_share=0.394, jitter_time=0.0663, level_log_mean=0.261,
                       level_log_std=0.796, size_log_mean=-2.24, size_log_std=0.732)


def reflect(x: np.ndarray, rate: np.ndarray, low: np.ndarray | float, high: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Fold a free path ``x`` into [low, high] by reflection at both ends (``low`` < ``high``, broadcastable), with
    its rate of change ``rate``: a value k reflections away from the interval is mirrored k times, and its rate
    changes sign when k is odd. Values already inside are returned unchanged (the same arrays when all are)."""
    outside = (x < low) | (x > high)
    if not outside.any():
        return x, rate
    width = high - low
    u = np.mod(x - low, 2.0 * width)  # position within one back-and-forth period
    odd = u > width  # an odd number of reflections: on the way back
    folded = low + np.where(odd, 2.0 * width - u, u)
    return np.where(outside, folded, x), np.where(outside & odd, -rate, rate)


def draw_extra(rng: np.random.Generator, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The draws of one track beyond the "cv" model's: normals (T + 1, 2) and uniforms (T, 2)."""
    return rng.standard_normal((n_frames + 1, 2)), rng.random((n_frames, 2))


def otb_paths(eps: np.ndarray, normals: np.ndarray, uniforms: np.ndarray, x0: np.ndarray, step: np.ndarray,
              levels: np.ndarray, bounds: np.ndarray, motion: OTBMotion) -> tuple[np.ndarray, np.ndarray]:
    """True boxes (B, T, 4) and their velocities (B, T, 4) from standard-normal ``eps`` (B, T − 1, 4),
    ``normals`` (B, T + 1, 2), ``uniforms`` (B, T, 2); per track the first box ``x0`` (B, 4) (cx, cy, w, h),
    the frame step h ``step`` (B,), ``levels`` (B, 2) = (σ_r, σ_ℓ) and the size ``bounds`` (B, 2) px."""
    B, T = uniforms.shape[:2]
    h = step[:, None, None]
    # sizes: reflected random walk of ℓ = log(w / w_0)
    increments = levels[:, 1, None, None] * np.sqrt(h) * eps[..., 2:]
    ell = np.concatenate([np.zeros((B, 1, 2)), np.cumsum(increments, axis=1)], axis=1)
    rate = np.concatenate([np.zeros((B, 1, 2)), increments / h], axis=1)
    sizes0 = x0[:, None, 2:4]
    ell, rate = reflect(ell, rate, np.log(bounds[:, None, :1] / sizes0), np.log(bounds[:, None, 1:] / sizes0))
    sizes = sizes0 * np.exp(ell)
    # centre velocity in box scales per second: cruise (Poisson switches) + AR(1) jitter
    sigma_c = levels[:, 0] * math.sqrt(motion.cruise_share)
    sigma_j = levels[:, 0] * math.sqrt(1.0 - motion.cruise_share)
    switch = uniforms < -np.expm1(-motion.switch_rate * h)
    switch[:, 0] = True
    last = np.maximum.accumulate(np.where(switch, np.arange(T)[None, :, None], 0), axis=1)
    cruise = sigma_c[:, None, None] * np.take_along_axis(normals[:, 1:], last, axis=1)
    jitter = np.empty((B, T, 2))
    for b in range(B):  # one track at a time: its arithmetic does not depend on the batch
        phi = math.exp(-step[b] / motion.jitter_time)
        drive = np.concatenate([normals[b, :1], math.sqrt(1.0 - phi * phi) * eps[b, :, :2]]) * sigma_j[b]
        jitter[b] = lfilter([1.0], [1.0, -phi], drive, axis=0)
    scale = np.sqrt(sizes[..., :1] * sizes[..., 1:])
    velocity = scale * (cruise + jitter)  # px/s
    centre = x0[:, None, :2] + np.concatenate([np.zeros((B, 1, 2)), np.cumsum(h * velocity[:, :-1], axis=1)], axis=1)
    return np.concatenate([centre, sizes], axis=-1), np.concatenate([velocity, sizes * rate], axis=-1)
