"""Detection errors of a real detection stream, added to any measured track: missed frames and wrong boxes.

Real streams (MOT15 public detections matched to ground-truth pedestrians) miss 44 % of an identity's frames on
average (quartiles 25–60 %), in runs of median 2 and up to 214 frames, and now and then match a wrong box. This
module corrupts B measured tracks y (B, T, 4) of (cx, cy, w, h) boxes in px the same way, per episode:

* **missed frames** (NaN rows of y; the truth stays) at the episode's miss rate π:
  ``"bernoulli"`` — each frame missed independently with probability π; ``"runs"`` — a two-state
  Gilbert–Elliott chain: from "detected" a miss run starts with probability p, a run goes on with probability
  1 − 1/L (L: the mean run length, frames), p = π / ((1 − π) L) so that the stationary miss rate is π, the
  chain's first state drawn from the stationary distribution. A mean run shorter than π / (1 − π) frames
  cannot reach π (p would exceed 1): L is raised to that bound (then every detected run lasts one frame);
* **wrong boxes** (outliers): each measured frame with ground truth, independently with the episode's outlier
  probability, is replaced by another nearby object's box — the true box's w and h both scaled by a
  log-normal factor exp(N(0, ``OUTLIER_LOG_SIZE_STD``²)) (the same aspect ratio: an object of the same kind
  at another depth), its centre moved from the true centre by d · h, d uniform in ``OUTLIER_SHIFT`` true box
  heights, in a uniformly random direction.

The first and the last measured frame of a track always stay measured (a real stream's episode runs from its
first to its last detection), so a track with two measured frames keeps them; frames the track already lacks
stay missing. Per episode, the miss rate is uniform in ``miss_rate_range``, L log-uniform in ``miss_run_range``,
the outlier probability uniform in ``outlier_rate_range`` (:class:`DetectionModel`).

Every random number comes from the episode's own generator (:meth:`DetectionModel.draw`: two calls per
episode, each vectorised over frames), so B episodes corrupted together equal each corrupted alone; the chain
itself is computed for all episodes and frames at once (:func:`gilbert_elliott`, no loop over frames).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DROPOUTS = ("none", "bernoulli", "runs")  # EnvConfig.detection_dropout
OUTLIER_LOG_SIZE_STD = 0.3  # std of the log size factor of a wrong box (0.55–1.8 × the true size at ±2 std)
OUTLIER_SHIFT = (0.5, 2.0)  # centre displacement of a wrong box, in true box heights (uniform)


@dataclass(frozen=True)
class DetectionDraw:
    """The random part of B episodes' detection errors: per episode the drawn ``miss_rate``, ``miss_run`` (L,
    frames) and ``outlier_rate`` (B,), and per frame ``uniform`` (4, B, T) — the miss draw, the outlier
    draw, the wrong box's shift and direction — and ``normal`` (B, T), its log size factor / std."""

    miss_rate: np.ndarray
    miss_run: np.ndarray
    outlier_rate: np.ndarray
    uniform: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class DetectionModel:
    """Which errors to add and the per-episode ranges they are drawn from (module docstring; the ``EnvConfig``
    fields ``detection_dropout``, ``miss_rate_range``, …). With ``dropout="none"`` and no outlier probability
    above 0 it adds nothing (:attr:`active` is False)."""

    dropout: str  # one of DROPOUTS
    miss_rate_range: tuple[float, float]  # (low, high), uniform, within [0, 1)
    miss_run_range: tuple[float, float]  # frames, (low, high), log-uniform, within [1, inf)
    outlier_rate_range: tuple[float, float]  # (low, high), uniform, within [0, 1]

    @property
    def active(self) -> bool:
        return self.dropout != "none" or self.outlier_rate_range[1] > 0

    def draw(self, rngs: list[np.random.Generator], n_frames: int) -> DetectionDraw:
        """The draws of ``len(rngs)`` episodes of ``n_frames`` frames, each from its own generator in two calls
        (3 + 4·T uniforms: the miss rate, run length and outlier rate, then the per-frame ones; T normals): an
        episode's draws depend neither on the other episodes nor on which errors are switched on."""
        uniform = np.empty((len(rngs), 3 + 4 * n_frames))
        normal = np.empty((len(rngs), n_frames))
        for b, rng in enumerate(rngs):
            rng.random(out=uniform[b])
            rng.standard_normal(out=normal[b])
        lows, highs = np.array([self.miss_rate_range, np.log(self.miss_run_range), self.outlier_rate_range]).T
        miss_rate, log_run, outlier_rate = (lows + (highs - lows) * uniform[:, :3]).T
        return DetectionDraw(miss_rate=miss_rate, miss_run=reachable_run(miss_rate, np.exp(log_run)),
                             outlier_rate=outlier_rate, normal=normal,
                             uniform=uniform[:, 3:].reshape(len(rngs), 4, n_frames).transpose(1, 0, 2))

    def parameters(self, drawn: DetectionDraw) -> list[dict[str, float]]:
        """Per episode, the drawn parameters of the errors in use: ``miss_rate`` (with dropout), ``miss_run``
        (the mean run length L after :func:`reachable_run`, "runs" only), ``outlier_rate`` (with outliers)."""
        keys = [k for k, used in (("miss_rate", self.dropout != "none"), ("miss_run", self.dropout == "runs"),
                                  ("outlier_rate", self.outlier_rate_range[1] > 0)) if used]
        return [{k: float(getattr(drawn, k)[b]) for k in keys} for b in range(len(drawn.miss_rate))]

    def apply(self, y: np.ndarray, truth: np.ndarray, drawn: DetectionDraw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``y`` (B, T, 4) with the errors of ``drawn`` against ``truth`` (B, T, 4): the new measurements
        (a copy), the frames made missing (B, T) and those given a wrong box (B, T)."""
        u_miss, u_outlier, u_shift, u_angle = drawn.uniform
        if self.dropout == "bernoulli":
            missed = u_miss < drawn.miss_rate[:, None]
        elif self.dropout == "runs":
            missed = gilbert_elliott(u_miss, drawn.miss_rate, drawn.miss_run)
        else:
            missed = np.zeros(u_miss.shape, dtype=bool)
        measured = finite_rows(y)
        missing = keep_ends(missed & measured, measured)
        outlier = u_outlier < drawn.outlier_rate[:, None]
        if outlier.any():
            outlier &= measured & ~missing & finite_rows(truth)
        out = y.copy()
        out[missing] = np.nan
        out[outlier] = wrong_boxes(truth[outlier], drawn.normal[outlier], u_shift[outlier], u_angle[outlier])
        return out, missing, outlier


def finite_rows(boxes: np.ndarray) -> np.ndarray:
    """Whether each box of ``boxes`` (..., 4) is finite (..., ) (4 column checks: faster than ``.all(axis=-1)``)."""
    ok = np.isfinite(boxes[..., 0])
    for k in range(1, 4):
        ok &= np.isfinite(boxes[..., k])
    return ok


def reachable_run(miss_rate: np.ndarray, miss_run: np.ndarray) -> np.ndarray:
    """The mean miss run L (frames) raised where needed to π / (1 − π), the shortest with which a
    Gilbert–Elliott chain reaches the miss rate π (its run-start probability p = π / ((1 − π) L) <= 1)."""
    return np.maximum(miss_run, miss_rate / (1.0 - miss_rate))


def gilbert_elliott(u: np.ndarray, miss_rate: np.ndarray, miss_run: np.ndarray) -> np.ndarray:
    """The miss states (B, T) of B two-state chains (module docstring) driven by uniforms ``u`` (B, T) on [0, 1):
    frame 0 is a miss if u < π (the stationary start); then, from "detected", a miss if u < p, and from "miss",
    still a miss if u < 1 − 1/L. ``miss_run`` (B,) must be reachable (:func:`reachable_run`).

    Each frame's u maps the previous state to the next by one of four maps: both branches true (miss whatever
    came before), both false (detected), only the "miss" branch true (the state is kept) or only the "detected"
    one (the state flips). So the state is that set at the last frame with a constant map (frame 0 counts as
    one), flipped once per flip since: computed for all frames at once, equal to the step-by-step chain."""
    p = miss_rate / ((1.0 - miss_rate) * miss_run)
    start = u < p[:, None]  # a miss run starts here, from "detected"
    stay = u < (1.0 - 1.0 / miss_run)[:, None]  # a miss run goes on here
    stay[:, 0] = start[:, 0] = u[:, 0] < miss_rate  # the stationary start: a constant map
    frames = np.arange(u.shape[1], dtype=np.int32)
    last_fixed = np.maximum.accumulate(np.where(stay == start, frames, 0), axis=1)
    parity = np.bitwise_xor.accumulate(start & ~stay, axis=1)  # of the flips so far
    rows = np.arange(len(u))[:, None]
    return stay[rows, last_fixed] ^ parity ^ parity[rows, last_fixed]


def keep_ends(missing: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """``missing`` (B, T) with each track's first and last ``measured`` (B, T) frame kept (set False)."""
    out = missing.copy()
    rows = np.arange(len(measured))
    out[rows, np.argmax(measured, axis=1)] = False
    out[rows, measured.shape[1] - 1 - np.argmax(measured[:, ::-1], axis=1)] = False
    return out


def wrong_boxes(truth: np.ndarray, normal: np.ndarray, u_shift: np.ndarray, u_angle: np.ndarray) -> np.ndarray:
    """The wrong boxes (..., 4) for true boxes ``truth`` (..., 4) (cx, cy, w, h; module docstring): w and h
    scaled by exp(``OUTLIER_LOG_SIZE_STD`` · ``normal``), the centre moved by ``u_shift`` (uniform on [0, 1) →
    ``OUTLIER_SHIFT``) true heights in the direction 2π ``u_angle`` (each (...))."""
    lo, hi = OUTLIER_SHIFT
    distance = (lo + (hi - lo) * u_shift) * truth[..., 3]
    angle = 2 * np.pi * u_angle
    size = np.exp(OUTLIER_LOG_SIZE_STD * normal)[..., None] * truth[..., 2:]
    centre = truth[..., :2] + distance[..., None] * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    return np.concatenate([centre, size], axis=-1)
