"""A SORT-style tracking-by-detection loop ([Bewley-SORT]) over a pluggable box filter
(:class:`bboxtune.agents.tracking.filter_bank.FilterBank`), with ByteTrack's two-stage association
([Zhang-ByteTrack]) as an option and causal per-track re-tuning of the filter
(:class:`bboxtune.agents.tracking.retune.CausalRetune`).

Every frame, as SORT's ``update``:

1. every live track's filter predicts its box in this frame (:meth:`FilterBank.predict`);
2. detections are matched to the predictions by the Hungarian assignment on IoU, pairs with IoU >= ``iou_threshold``
   (:func:`bboxtune.agents.tracking.association.assign`). With ``two_stage`` (ByteTrack): first the detections with
   score >= ``high_score`` against every track, then those with ``low_score`` <= score < ``high_score`` against
   the tracks left, at IoU >= ``low_iou_threshold``; detections below ``low_score`` are dropped;
3. matched tracks update their filter with the detection, the others predict only (one filter call for all);
4. every unmatched detection starts a track (with ``two_stage``: only those with score >= ``new_track_score``),
   in the same filter call;
5. a track is reported when it was matched in this frame and has been matched in ``min_hits`` frames in a row
   (or the frame is one of the first ``min_hits``), with its filtered box; a track unmatched for more than
   ``max_age`` frames ends.

Identities count from 1 in order of birth. SORT's defaults: ``max_age`` 1, ``min_hits`` 3, ``iou_threshold`` 0.3.
Boxes are xywh px (MOT Challenge). The loop is causal: frame t uses detections up to t only.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from bboxtune import filters
from bboxtune.agents.tracking.association import assign, iou_matrix
from bboxtune.agents.tracking.filter_bank import FilterBank
from bboxtune.agents.tracking.retune import CausalRetune, Retuner
from bboxtune.agents.tracking.search_tune import BACKEND, CausalSearch, SearchSettings
from bboxtune.envs.data.boxes import COORD_RULE, MAX_COORD

if TYPE_CHECKING:
    from bboxtune.agents.smoothing.tuner import Tuner

TUNED = "tuned"  # the filter chosen per track by a trained tuner (make_tracker)
SEARCH = "search"  # the filter chosen per track by the causal prediction search (make_tracker)


@dataclass(frozen=True)
class TrackerConfig:
    """The tracker's settings (SORT's defaults; ByteTrack's association off)."""

    max_age: int = 1  # frames a track survives without a matched detection
    min_hits: int = 3  # matched frames in a row before a track is reported
    iou_threshold: float = 0.3  # least IoU of a matched (prediction, detection) pair
    two_stage: bool = False  # ByteTrack's association by detection score
    high_score: float = 0.5  # two_stage: a detection with score >= this is matched first (detector's units)
    low_score: float = 0.1  # two_stage: detections below this are dropped
    low_iou_threshold: float = 0.5  # two_stage: least IoU of a low-score detection's match
    new_track_score: float = 0.6  # two_stage: least score of a detection that starts a track

    def __post_init__(self) -> None:
        for name in ("max_age", "min_hits"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value <= 10**6:
                raise ValueError(f"{name}={value!r}; allowed: an integer 0..1000000")
        for name in ("iou_threshold", "low_iou_threshold"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= 1:
                raise ValueError(f"{name}={value!r}; allowed 0 < {name} <= 1")
        for name in ("high_score", "low_score", "new_track_score"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ValueError(f"{name}={value!r}; allowed: a finite number")
        if self.two_stage and not self.low_score <= self.high_score:
            raise ValueError(f"low_score={self.low_score} > high_score={self.high_score}; allowed low <= high")


@dataclass
class _Tracks:
    """Bookkeeping of the live tracks, row i = the filter bank's row i."""

    ids: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    streak: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))  # matched frames in a row
    unmatched: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))  # frames since the last match

    def append(self, ids: np.ndarray) -> None:
        self.ids = np.concatenate([self.ids, ids])
        self.streak = np.concatenate([self.streak, np.zeros(len(ids), dtype=np.int64)])
        self.unmatched = np.concatenate([self.unmatched, np.zeros(len(ids), dtype=np.int64)])

    def keep(self, index: np.ndarray) -> None:
        self.ids, self.streak, self.unmatched = self.ids[index], self.streak[index], self.unmatched[index]


@dataclass(frozen=True)
class FrameResult:
    """The tracks reported in one frame."""

    frame: int
    ids: np.ndarray  # (r,) int64 identities
    boxes: np.ndarray  # (r, 4) xywh px, the filtered boxes
    scores: np.ndarray  # (r,) the matched detections' scores


def check_detections(boxes: np.ndarray, scores: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``boxes`` (k, 4) xywh px and ``scores`` (k,) as float arrays, after the checks every detection passes: finite
    x, y and w, h > 0 within :data:`~bboxtune.envs.data.boxes.MAX_COORD`, finite scores; errors name the row."""
    b, s = np.asarray(boxes, dtype=float), np.asarray(scores, dtype=float)
    if b.ndim != 2 or b.shape[1] != 4 or s.shape != (len(b),):
        raise ValueError(f"boxes has shape {b.shape}, scores {s.shape}; allowed: (k, 4) xywh px and (k,)")
    bad = ~(np.isfinite(b).all(axis=1) & (b[:, 2:] > 0).all(axis=1) & (np.abs(b) <= MAX_COORD).all(axis=1))
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"boxes[{i}] = {b[i].tolist()}; allowed: finite x, y and w, h > 0 with {COORD_RULE}")
    if not np.isfinite(s).all():
        i = int(np.argmax(~np.isfinite(s)))
        raise ValueError(f"scores[{i}] = {float(s[i])!r}; allowed: a finite number")
    return b, s


class Tracker:
    """Online SORT-style tracker over ``bank`` (its back end and parameters) with ``config``; ``retune`` re-tunes
    each track's filter from its own past detections (None: the bank's parameters throughout)."""

    def __init__(self, bank: FilterBank, config: TrackerConfig | None = None, retune: Retuner | None = None) -> None:
        self.bank, self.config, self.retune = bank, config or TrackerConfig(), retune
        self._tracks = _Tracks()
        self._next_id = 1
        self._frames = 0

    def step(self, boxes: np.ndarray, scores: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One frame: detections ``boxes`` (k, 4) xywh px with ``scores`` (k,); returns the reported tracks'
        identities (r,), filtered boxes (r, 4) and matched scores (r,)."""
        return self._step(*check_detections(boxes, scores))

    def _step(self, boxes: np.ndarray, scores: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cfg, tracks = self.config, self._tracks
        self._frames += 1
        predicted = self.bank.predict()
        det = np.arange(len(boxes))
        if cfg.two_stage:
            det = det[scores >= cfg.low_score]
            high, low = det[scores[det] >= cfg.high_score], det[scores[det] < cfg.high_score]
        else:
            high, low = det, det[:0]
        pairs, left, new = assign(iou_matrix(predicted, boxes[high]), cfg.iou_threshold)
        matched_track, matched_det = pairs[:, 0], high[pairs[:, 1]]
        new = high[new]
        if len(low) and len(left):
            second, _, _ = assign(iou_matrix(predicted[left], boxes[low]), cfg.low_iou_threshold)
            matched_track = np.concatenate([matched_track, left[second[:, 0]]])
            matched_det = np.concatenate([matched_det, low[second[:, 1]]])
        if cfg.two_stage:
            new = new[scores[new] >= cfg.new_track_score]
        n = self.bank.n
        measured = np.full((n, 4), np.nan)
        measured[matched_track] = boxes[matched_det]
        if self.retune is not None:
            self.retune.observe(measured)
        born = np.array(boxes[new], dtype=float).reshape(-1, 4)
        estimates = self.bank.update(measured, born)  # the new tracks start in the same call (rows n … n + k − 1)
        hit = np.zeros(n, dtype=bool)
        hit[matched_track] = True
        tracks.streak = np.where(hit, tracks.streak + 1, 0)
        tracks.unmatched = np.where(hit, 0, tracks.unmatched + 1)
        matched_score = np.full(n, np.nan)
        matched_score[matched_track] = scores[matched_det]
        if self.retune is not None:
            self.retune.retune(self.bank)
            self.retune.start(boxes[new])
        tracks.append(np.arange(self._next_id, self._next_id + len(new), dtype=np.int64))
        self._next_id += len(new)
        estimates = np.concatenate([estimates, born])
        matched_score = np.concatenate([matched_score, scores[new]])
        recent = tracks.unmatched < 1
        report = recent & ((tracks.streak >= cfg.min_hits) | (self._frames <= cfg.min_hits))
        out = (tracks.ids[report], estimates[report], matched_score[report])
        alive = np.flatnonzero(tracks.unmatched <= cfg.max_age)
        if len(alive) < len(tracks.ids):
            tracks.keep(alive)
            self.bank.keep(alive)
            if self.retune is not None:
                self.retune.keep(alive)
        return out

    def run(self, frames: np.ndarray, boxes: np.ndarray, scores: np.ndarray, n_frames: int | None = None
            ) -> Iterator[FrameResult]:
        """Track a whole sequence of detections (``frames`` (N,) 1-based, ``boxes`` (N, 4) xywh, ``scores`` (N,)),
        frame 1 … ``n_frames`` (default: the last detection's frame), frames without detections included."""
        boxes, scores = check_detections(boxes, scores)
        order = np.argsort(frames, kind="stable")
        frames, boxes, scores = frames[order], boxes[order], scores[order]
        last = int(frames[-1]) if n_frames is None and len(frames) else int(n_frames or 0)
        bounds = np.searchsorted(frames, np.arange(1, last + 2))
        for t in range(1, last + 1):
            lo, hi = bounds[t - 1], bounds[t]
            ids, est, sc = self._step(boxes[lo:hi], scores[lo:hi])
            yield FrameResult(t, ids, est, sc)


def make_tracker(filter_name: str, tau: float, *, params: Mapping[str, Any] | None = None, tuner: Tuner | None = None,
                 config: TrackerConfig | None = None, window: int = 10, history: int = 100,
                 search: SearchSettings | None = None) -> Tracker:
    """A tracker whose filter is ``filter_name``: a back end of :mod:`bboxtune.filters` (``sort_kf``, ``bytetrack_kf``,
    ``kf``, …) with ``params``; :data:`TUNED`: ``tuner``'s back end re-tuned per track every ``window`` frames
    from its last ``history`` frames (:class:`CausalRetune`), starting from the back end's stock parameters; or
    :data:`SEARCH`: SORT's filter with noise scales chosen per track by :class:`CausalSearch` with ``search``
    (its own window and history; default :class:`SearchSettings`)."""
    if filter_name == SEARCH:
        if tuner is not None or params:
            raise ValueError(f"filter {SEARCH!r} takes no tuner and no params (the search sets them)")
        return Tracker(FilterBank(BACKEND, tau), config, CausalSearch(tau, search))
    if search is not None:
        raise ValueError(f"search settings are for filter {SEARCH!r}, not {filter_name!r}")
    if filter_name != TUNED:
        if tuner is not None:
            raise ValueError(f"a tuner is for filter {TUNED!r}; filter {filter_name!r} takes params")
        return Tracker(FilterBank(filter_name, tau, params), config)
    if tuner is None or params:
        raise ValueError(f"filter {TUNED!r} needs a tuner and takes no params (the tuner sets them)")
    stock = filters.filter_class(tuner.backend).DEFAULTS
    bank = FilterBank(tuner.backend, tau, {name: stock[name] for name in tuner.parameters})
    return Tracker(bank, config, CausalRetune(tuner, tau, window=window, history=history))
