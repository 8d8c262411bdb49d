"""Causal per-track re-tuning inside a tracker: a track's filter parameters are chosen from its own past only.

:class:`TrackHistories` keeps, for every live track, its last ``history`` frames of matched detections (NaN rows
for frames without one; never a future frame, never a ground truth) and says which tracks are due: every
``window`` frames of a track's life, from its ``first``-th frame on. The chosen parameters take effect from the
next frame on — as ``bboxtune/FilterRetune-v0`` re-tunes every W frames; before its first re-tune a track runs with
the bank's parameters (the stock values). A history holds detections the tracker checked
(:func:`bboxtune.agents.tracking.sort_tracker.check_detections`: :func:`bboxtune.agents.smoothing.tuner.check_boxes`'s
rule) and NaN rows, at least ``first`` >= :data:`~bboxtune.agents.smoothing.tuner.MIN_FRAMES` frames, so
:class:`CausalRetune` passes it to :meth:`~bboxtune.agents.smoothing.tuner.Tuner.tune_checked` once it holds
:data:`~bboxtune.agents.smoothing.tuner.MIN_MEASURED` detections. Two re-tuners (:class:`Retuner`) choose the parameters:

* :class:`CausalRetune`: a trained tuner (:class:`bboxtune.agents.smoothing.tuner.Tuner`, e.g. the pretrained
  ``mot15_det``) sees the history; a track with fewer than two matched detections in view keeps its parameters;
* :class:`bboxtune.agents.tracking.search_tune.CausalSearch`: a search over candidate parameters by how well each
  would have predicted the track's past detections.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from bboxtune.agents.smoothing.tuner import MIN_FRAMES, MIN_MEASURED, check_tau

if TYPE_CHECKING:
    from bboxtune.agents.smoothing.tuner import Tuner
    from bboxtune.agents.tracking.filter_bank import FilterBank


def check_count(name: str, value: object, low: int) -> int:
    """An integer ``low`` … 10⁶ (not a bool); ValueError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= 10**6:
        raise ValueError(f"{name}={value!r}; allowed: an integer {low}..1000000")
    return int(value)


class Retuner(Protocol):
    """What a :class:`bboxtune.agents.tracking.sort_tracker.Tracker` calls to re-tune its tracks' filters."""

    def start(self, boxes: np.ndarray) -> None: ...
    def observe(self, measured: np.ndarray) -> None: ...
    def keep(self, index: np.ndarray) -> None: ...
    def retune(self, bank: FilterBank) -> None: ...


class TrackHistories:
    """The last ``history`` frames of every live track (rows as the filter bank's) and the tracks due for a re-tune
    every ``window`` frames from their ``first`` frame on."""

    def __init__(self, window: int, history: int, first: int, least_history: int = 1) -> None:
        self.window = check_count("window", window, 1)
        self.history = check_count("history", history, least_history)
        self.first = check_count("first", first, 1)
        self.y = np.full((0, self.history, 4), np.nan)  # the last `history` frames of each live track, xywh px
        self.age = np.empty(0, dtype=np.int64)  # frames each track has lived
        self.calls = 0  # tracks re-tuned so far

    def start(self, boxes: np.ndarray) -> None:
        """New tracks at their first detections ``boxes`` (k, 4) xywh (appended, as the filter bank's rows)."""
        if not len(boxes):
            return
        fresh = np.full((len(boxes), self.history, 4), np.nan)
        fresh[:, -1] = boxes
        self.y = np.concatenate([self.y, fresh])
        self.age = np.concatenate([self.age, np.ones(len(boxes), dtype=np.int64)])

    def observe(self, measured: np.ndarray) -> None:
        """One more frame of every live track: its matched detection (n, 4) xywh, NaN rows for none."""
        self.y[:, :-1] = self.y[:, 1:]
        self.y[:, -1] = measured
        self.age += 1

    def keep(self, index: np.ndarray) -> None:
        """Keep only the tracks ``index``, in that order."""
        self.y, self.age = self.y[index], self.age[index]

    def due(self) -> np.ndarray:
        """The rows of the tracks due now: age ``first`` + a multiple of ``window``."""
        return np.flatnonzero((self.age >= self.first) & ((self.age - self.first) % self.window == 0))

    def seen(self, row: int) -> np.ndarray:
        """The frames of track ``row`` in view: its last min(age, history) frames (T, 4) xywh."""
        return self.y[row, -min(int(self.age[row]), self.history):]


class CausalRetune(TrackHistories):
    """Re-tunes the live tracks of a tracker with ``tuner`` (frame interval ``tau`` s) every ``window`` frames
    from a track's ``first`` frame on, seeing at most its last ``history`` frames."""

    def __init__(self, tuner: Tuner, tau: float, window: int = 10, history: int = 100, first: int = MIN_FRAMES) -> None:
        check_count("first", first, MIN_FRAMES)
        super().__init__(window, history, first, least_history=MIN_FRAMES)
        self.tuner, self.tau = tuner, check_tau(tau)

    def retune(self, bank: FilterBank) -> None:
        """Set new parameters in ``bank`` for every track due."""
        chosen: list[int] = []
        values: dict[str, list[float]] = {name: [] for name in self.tuner.parameters}
        for row in self.due():
            seen = self.seen(int(row))
            if int(np.isfinite(seen[:, 0]).sum()) < MIN_MEASURED:
                continue
            params = self.tuner.tune_checked(seen, self.tau)  # the tracker's checked detections (module docstring)
            chosen.append(int(row))
            for name in values:
                values[name].append(float(params[name]))
        if chosen:
            bank.set_params(np.array(chosen), {name: np.array(v) for name, v in values.items()})
            self.calls += len(chosen)
