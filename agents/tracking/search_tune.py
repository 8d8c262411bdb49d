"""Causal, tracking-aware per-track tuning by search: every ``window`` frames each live track picks its filter's
parameters from a candidate set by how well each candidate would have predicted the track's own past detections.

Association matches a detection to where the filter *predicts* the track, so the score of a candidate is the
quantity association uses: the IoU of the box the candidate predicts at each past frame that has a matched
detection — predicted from the frames before it only, one step after a detection and several steps across missed
frames (the prediction at the frame the track is re-detected, where a too slow or too fast filter loses the track
or takes another's detection) — with that detection, counted up to ``cap`` (association needs an IoU above its
threshold, not a perfect box: a cap below 1 spends the score on the frames near losing the track) and averaged
over the track's last ``history`` frames (:func:`candidate_scores`). A missing prediction at such a frame counts as
IoU 0.

The candidates are SORT's filter with two noise scales (:class:`bboxtune.filters.sort_kf.ScaledSortKF`): every
pair (k_v, k_r) with k = ``width`` ** u, u on ``steps`` points evenly spaced in [−1, 1] (:func:`candidate_grid`;
``steps`` odd, so the stock filter k_v = k_r = 1 is one of them). The choice (:meth:`CausalSearch.retune`):

* a track runs SORT's stock filter until it has ``min_scored`` scored frames in view (a sensible default before
  enough history);
* then the candidate with the best score, where every candidate but the stock one pays ``margin`` (mean IoU) and
  ties go to the stock one (with a cap below 1 many candidates reach the cap on every frame): shrinkage toward
  SORT's filter, which the tracker keeps unless the evidence for another is clear.

All tracks due in a frame and all candidates run in one call: a compiled kernel that returns only each track's
chosen candidate (:func:`bboxtune.agents.tracking.search_kernels.choose_candidates`), or, with ``$BBOXTUNE_JIT=0``,
a batched numpy recursion ((tracks × candidates) columns over ``history`` frames) with the same result.
Causal: a track's history holds its matched detections up to the current frame; never a
future frame, never a ground truth. Tracks are re-tuned together on every ``window``-th frame of the sequence
(those that have lived ``min_scored`` + 1 frames), so the search costs one call per ``window`` frames.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bboxtune import filters
from bboxtune.agents.tracking.retune import TrackHistories, check_count
from bboxtune.agents.tracking.search_kernels import AREA, LONGEST, choose_candidates, prior_means
from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.data.metrics import iou
from bboxtune.filters import jit
from bboxtune.filters.box_state import HeightVariance, initiate, update_state
from bboxtune.filters.bytetrack_kf import BoxKF, M, check_boxes
from bboxtune.filters.sort_kf import ScaledSortKF, SortKF

if TYPE_CHECKING:
    from bboxtune.agents.tracking.filter_bank import FilterBank

BACKEND = ScaledSortKF.name  # the candidates' back end, the tracker's filter bank's
STOCK: dict[str, float] = dict(ScaledSortKF.DEFAULTS)  # SORT's filter


@dataclass(frozen=True)
class SearchSettings:
    """The search's hyperparameters (module docstring)."""

    window: int = 5  # frames between re-tunes
    history: int = 50  # past frames a track's candidates are scored on
    width: float = 4.0  # the grid's largest scale factor (its smallest: 1 / width)
    steps: int = 5  # grid points per scale (odd)
    margin: float = 0.0  # mean-IoU advantage a candidate needs over SORT's stock filter
    min_scored: int = 5  # scored frames a track needs before it leaves SORT's stock filter
    cap: float = 0.5  # IoU counted up to this (the association needs IoU >= its threshold, not a perfect box)

    def __post_init__(self) -> None:
        check_count("window", self.window, 1)
        check_count("history", self.history, 2)
        check_count("min_scored", self.min_scored, 1)
        if isinstance(self.steps, bool) or not isinstance(self.steps, int) or not (1 <= self.steps <= 99
                                                                                   and self.steps % 2):
            raise ValueError(f"steps={self.steps!r}; allowed: an odd integer 1..99")
        if isinstance(self.width, bool) or not isinstance(self.width, (int, float)) or not 1 <= self.width <= 1e6:
            raise ValueError(f"width={self.width!r}; allowed 1 <= width <= 1e6")
        if isinstance(self.cap, bool) or not isinstance(self.cap, (int, float)) or not 0 < self.cap <= 1:
            raise ValueError(f"cap={self.cap!r}; allowed 0 < cap <= 1 (IoU)")
        if isinstance(self.margin, bool) or not isinstance(self.margin, (int, float)) or not 0 <= self.margin <= 1:
            raise ValueError(f"margin={self.margin!r}; allowed 0 <= margin <= 1 (mean IoU)")


def candidate_grid(width: float, steps: int) -> dict[str, np.ndarray]:
    """The candidates ``{name: (steps²,)}`` of :class:`ScaledSortKF`: every pair of scales ``width`` ** u, u on
    ``steps`` points in [−1, 1].

    >>> grid = candidate_grid(4.0, 3)
    >>> grid["velocity_noise_scale"].tolist(), grid["measurement_noise_scale"].tolist()
    ([0.25, 0.25, 0.25, 1.0, 1.0, 1.0, 4.0, 4.0, 4.0], [0.25, 1.0, 4.0, 0.25, 1.0, 4.0, 0.25, 1.0, 4.0])
    """
    SearchSettings(width=width, steps=steps)  # checked
    scales = float(width) ** np.linspace(-1.0, 1.0, steps)
    velocity, measurement = np.meshgrid(scales, scales, indexing="ij")
    return {"velocity_noise_scale": velocity.ravel(), "measurement_noise_scale": measurement.ravel()}


def predicted_boxes(kf: BoxKF, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What ``kf`` predicts for histories ``y`` (n, T, 4) xywh px (NaN rows: no detection), track i with row i of
    ``kf``'s per-track parameters (a scalar: every track): the boxes (n, T, 4) xywh predicted at every frame from the
    frames before it (as the tracker predicts a track before association), and where they are scored (n, T): frames
    with a detection after the track's first one. The recursion is the batch filter's: predict, update, initiate at
    the first detection."""
    y = np.asarray(y, dtype=float)
    if y.ndim != 3 or y.shape[2] != M:
        raise ValueError(f"y has shape {y.shape}; allowed (n, T, {M}) xywh boxes")
    Y = xywh_to_cxcywh(y)
    check_boxes(Y)
    n, T, _ = Y.shape
    noise = kf._noise({name: np.broadcast_to(value, (n,)) for name, value in kf.params.items()})
    P_start, Q = HeightVariance(noise.start, (2, M, n)), HeightVariance(noise.process, (2, M, n))
    R = HeightVariance(noise.measurement, (M, n))
    z = kf._measure(Y.transpose(1, 2, 0))  # (T, 4, n)
    variances = (P_start.fixed, Q.fixed, R.fixed)
    if jit.enabled() and isinstance(kf, SortKF) and all(v is not None for v in variances):
        prior, scored = prior_means(np.ascontiguousarray(z), *(np.ascontiguousarray(v) for v in variances), AREA)
    else:  # the reference: the batch filter's own steps
        prior, scored = _prior_means(kf, z, P_start, Q, R)
    boxes = prior.transpose(2, 0, 1).copy()
    kf._to_boxes(boxes)
    return cxcywh_to_xywh(boxes), scored.T


def _prior_means(kf: BoxKF, z: np.ndarray, P_start: HeightVariance, Q: HeightVariance, R: HeightVariance
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bboxtune.agents.tracking.search_kernels.prior_means` in numpy, for any :class:`BoxKF`: the predicted
    means (T, 4, n) on measured coordinates ``z`` (T, 4, n) and where they are scored (T, n)."""
    T, _, n = z.shape
    detected = ~np.isnan(z[:, 0])  # (T, n)
    X = np.full((5, M, n), np.nan)  # the state layout of bboxtune.filters.bytetrack_kf
    prior = np.empty((T, M, n))
    scored = np.zeros((T, n), dtype=bool)
    for t in range(T):
        began = ~np.isnan(X[0, 0])
        kf.predict_state(X, Q)
        prior[t] = X[0]
        here = detected[t]
        scored[t] = here & began
        update_state(X, np.where(here, z[t], 0.0), R, None if here.all() else here.astype(float))
        new = np.flatnonzero(here & ~began)
        if len(new):
            initiate(X, z[t][:, new], P_start, new)
    return prior, scored


def candidate_scores(kf: ScaledSortKF, y: np.ndarray, candidates: Mapping[str, np.ndarray], cap: float = 1.0
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The mean prediction IoU (n, C), each frame's IoU counted up to ``cap``, of each of the C ``candidates``
    (``{name: (C,)}``, ``kf``'s parameters) on each history ``y`` (n, T, 4) xywh px (module docstring; NaN without
    a scored frame), and the scored frames (n,) — one batched recursion over the n × C pairs."""
    sizes = {len(np.atleast_1d(v)) for v in candidates.values()}
    if set(candidates) != set(kf.PER_TRACK) or len(sizes) != 1:
        raise ValueError(f"candidates has {sorted(candidates)}; allowed: equal-length arrays of {list(kf.PER_TRACK)}")
    n, n_candidates = len(y), sizes.pop()
    tiled = {name: np.tile(np.asarray(values, dtype=float), n) for name, values in candidates.items()}
    each = type(kf)(kf.model, **tiled)  # row i * C + c: track i, candidate c
    boxes, scored = predicted_boxes(each, np.repeat(np.asarray(y, dtype=float), n_candidates, axis=0))
    overlap = np.where(scored, np.minimum(np.nan_to_num(iou(boxes, np.repeat(y, n_candidates, axis=0)), nan=0.0), cap), 0.0)
    counts = scored.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = overlap.sum(axis=1) / counts
    return mean.reshape(n, n_candidates), counts.reshape(n, n_candidates)[:, 0]


class CausalSearch(TrackHistories):
    """Re-tunes the live tracks of a tracker (frame interval ``tau`` s) by the search of the module docstring with
    ``settings``; the tracker's filter bank must run :data:`BACKEND`. With the compiled kernels the whole choice
    runs in :func:`bboxtune.agents.tracking.search_kernels.choose_candidates` (histories up to
    :data:`~bboxtune.agents.tracking.search_kernels.LONGEST` frames); otherwise in numpy (:func:`candidate_scores`),
    with the same result."""

    def __init__(self, tau: float, settings: SearchSettings | None = None) -> None:
        self.settings = settings or SearchSettings()
        super().__init__(self.settings.window, self.settings.history, self.settings.min_scored + 1, least_history=2)
        self.kf = ScaledSortKF(filters.constant_velocity(tau, ndim=M))
        self.candidates = candidate_grid(self.settings.width, self.settings.steps)
        self.stock = int(np.flatnonzero(np.all([self.candidates[k] == v for k, v in STOCK.items()], axis=0))[0])
        self._frames = 0
        n_candidates = self.settings.steps ** 2
        noise = self.kf._noise(self.candidates)  # the candidates' fixed variances, built once
        self._variances = tuple(np.ascontiguousarray(HeightVariance(pair, shape).fixed) for pair, shape in (
            (noise.start, (2, M, n_candidates)), (noise.process, (2, M, n_candidates)),
            (noise.measurement, (M, n_candidates))))

    def observe(self, measured: np.ndarray) -> None:
        super().observe(measured)
        self._frames += 1

    def retune(self, bank: FilterBank) -> None:
        """On every ``window``-th frame, set in ``bank`` the chosen candidate of every track old enough."""
        if self._frames % self.window:
            return
        due = np.flatnonzero(self.age >= self.first)
        if not len(due):
            return
        seen = self.y[due, -min(int(self.age[due].max()), self.history):]
        if jit.enabled() and seen.shape[1] <= LONGEST:  # the boxes were checked by the bank's update
            s = self.settings
            choice = choose_candidates(np.ascontiguousarray(seen), *self._variances, AREA, float(s.cap),
                                       float(s.margin), self.stock, s.min_scored)
        else:
            choice = self._reference_choice(seen)
        bank.set_params(due, {name: values[choice] for name, values in self.candidates.items()})
        self.calls += len(due)

    def _reference_choice(self, seen: np.ndarray) -> np.ndarray:
        """The chosen candidate (n,) of each history ``seen`` (n, T, 4) xywh, in numpy (module docstring)."""
        scores, counts = candidate_scores(self.kf, seen, self.candidates, self.settings.cap)
        penalty = np.full(scores.shape[1], self.settings.margin)
        penalty[self.stock] = 0.0
        adjusted = np.nan_to_num(scores, nan=-1.0) - penalty
        choice = np.argmax(adjusted, axis=1)
        choice[(adjusted[:, self.stock] >= adjusted.max(axis=1)) | (counts < self.settings.min_scored)] = self.stock
        return choice
