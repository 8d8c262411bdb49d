"""The box filters of a tracker's live tracks: one batched :mod:`bboxtune.filters` back end over all of them.

A tracker asks, every frame, where each track is expected (:meth:`FilterBank.predict`), then feeds each track its
matched detection or nothing (:meth:`FilterBank.update`), starts tracks (:meth:`FilterBank.start`), ends them
(:meth:`FilterBank.keep`) and may re-tune some (:meth:`FilterBank.set_params`, from the next frame on). Two engines
with one interface:

* the trackers' own filters (``bytetrack_kf``, ``sort_kf``): :class:`bboxtune.filters.box_online.OnlineBoxKF`, the
  batch recursion one frame at a time (the tracker's speed path);
* every other back end: :class:`CarryFilter`, the back end's ``positions_from`` with its carry (the Kalman family's
  :class:`bboxtune.filters.base.Carry`, the FIR family's :class:`bboxtune.filters.history.History`), one call for
  the prediction and one for the update per frame.

Either way the prediction is the estimate at a frame without a measurement — the back end's own predict step
(exactly SORT's and ByteTrack's ``predict`` for ``sort_kf`` / ``bytetrack_kf``). Boxes are xywh px in and out; the
filters see (cx, cy, w, h). Parameters are the back end's ``PER_TRACK`` ones, per track.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from typing import Any, Protocol

import numpy as np

from bboxtune import filters
from bboxtune.filters.base import Carry
from bboxtune.filters.box_online import OnlineBoxKF, track_params
from bboxtune.filters.bytetrack_kf import BoxKF
from bboxtune.filters.fir_core import FIRFilter
from bboxtune.filters.history import History
from bboxtune.filters.online_carry import OnlineKalman
from bboxtune.filters.online_fir import OnlineFIR

M = 4  # measured coordinates of a box: cx, cy, w, h


class OnlineFilter(Protocol):
    """What :class:`FilterBank` runs: n live tracks in (cx, cy, w, h) px."""

    @property
    def n(self) -> int: ...
    def predict(self) -> np.ndarray: ...
    def update(self, boxes: np.ndarray, births: np.ndarray | None = None) -> np.ndarray: ...
    def start(self, boxes: np.ndarray, params: Mapping[str, Any] | None = None) -> None: ...
    def keep(self, index: np.ndarray) -> None: ...
    def set_params(self, rows: np.ndarray, params: Mapping[str, Any]) -> None: ...


def concatenate(first: Carry | History, second: Carry | History) -> Carry | History:
    """The carry of the tracks of ``first`` followed by those of ``second`` (histories of different lengths are
    aligned at their last frame; the shorter one is led by missing frames)."""
    if isinstance(first, History) and isinstance(second, History):
        length = max(first.y.shape[1], second.y.shape[1])
        padded = [np.concatenate([np.full((h.y.shape[0], length - h.y.shape[1], M), np.nan), h.y], axis=1)
                  for h in (first, second)]
        return History(np.concatenate(padded))
    if isinstance(first, Carry) and isinstance(second, Carry):
        joined: dict[str, Any] = {f.name: None if getattr(first, f.name) is None else
                                  np.concatenate([getattr(first, f.name), getattr(second, f.name)]) for f in fields(Carry)}
        return Carry(**joined)
    raise TypeError(f"cannot join a {type(first).__name__} and a {type(second).__name__}")


class CarryFilter:
    """Any back end ``f`` (a :class:`bboxtune.filters.Filter` of a 4-coordinate model) run online through its carry,
    with per-track parameters (new tracks start with ``f``'s)."""

    def __init__(self, f: filters.Filter) -> None:
        self.f = f
        self.params: dict[str, np.ndarray] = {name: np.empty(0) for name in f.PER_TRACK}
        self._carry: Carry | History | None = None
        self._n = 0

    @property
    def n(self) -> int:
        return self._n

    def _filter(self) -> filters.Filter:
        fixed = {k: v for k, v in self.f.params.items() if k not in self.params}
        return type(self.f)(self.f.model, **fixed, **self.params)

    def predict(self) -> np.ndarray:
        if self._n == 0:
            return np.empty((0, M))
        return self._filter().positions_from(np.full((self._n, 1, M), np.nan), self._carry)[0][:, 0]

    def update(self, boxes: np.ndarray, births: np.ndarray | None = None) -> np.ndarray:
        if boxes.shape != (self._n, M):
            raise ValueError(f"boxes has shape {boxes.shape}; allowed ({self._n}, {M}): one row per live track")
        out = np.empty((0, M))
        if self._n:
            est, self._carry = self._filter().positions_from(boxes[:, None], self._carry)
            out = est[:, 0]
        if births is not None:
            self.start(births)
        return out

    def start(self, boxes: np.ndarray, params: Mapping[str, Any] | None = None) -> None:
        k = len(boxes)
        if k == 0:
            return
        given = type(self.f)(self.f.model, **{**self.f.params, **(params or {})}).params  # validated
        first = {name: np.broadcast_to(np.asarray(given[name], dtype=float), (k,)) for name in self.params}
        fixed = {key: value for key, value in given.items() if key not in self.params}
        _, carry = type(self.f)(self.f.model, **fixed, **first).positions_from(boxes[:, None])
        self._carry = carry if self._carry is None else concatenate(self._carry, carry)
        self.params = {name: np.concatenate([self.params[name], first[name]]) for name in self.params}
        self._n += k

    def keep(self, index: np.ndarray) -> None:
        index = np.asarray(index, dtype=np.int64)
        self._carry = None if len(index) == 0 or self._carry is None else self._carry.take(index)
        self.params = {name: values[index] for name, values in self.params.items()}
        self._n = len(index)

    def set_params(self, rows: np.ndarray, params: Mapping[str, Any]) -> None:
        self.params = track_params(self.f, self.params, rows, params)


def _xywh(boxes: np.ndarray) -> np.ndarray:
    """:func:`bboxtune.envs.data.boxes.cxcywh_to_xywh` of an (n, 4) float array, without its checks (every frame)."""
    out = boxes.copy()
    out[:, :2] -= 0.5 * boxes[:, 2:]
    return out


def _cxcywh(boxes: np.ndarray) -> np.ndarray:
    """:func:`bboxtune.envs.data.boxes.xywh_to_cxcywh` of an (n, 4) array, without its checks (every frame)."""
    boxes = np.asarray(boxes, dtype=float)
    if boxes.ndim != 2 or boxes.shape[1] != M:
        raise ValueError(f"boxes has shape {boxes.shape}; allowed (n, {M}) xywh boxes")
    out = boxes.copy()
    out[:, :2] += 0.5 * boxes[:, 2:]
    return out


class FilterBank:
    """The filters of the live tracks (row i = the i-th track the tracker keeps): back end ``backend`` at frame
    interval ``tau`` (s) with ``params`` (``{name: value}``; the back end's defaults where not given) for new tracks.

    >>> bank = FilterBank("sort_kf", 1 / 30)
    >>> bank.start(np.array([[10.0, 20.0, 4.0, 8.0]])).tolist()
    [[10.0, 20.0, 4.0, 8.0]]
    >>> bank.update(np.array([[12.0, 20.0, 4.0, 8.0]])).round(2).tolist(), bank.predict().round(2).tolist()
    ([[12.0, 20.0, 4.0, 8.0]], [[14.0, 20.0, 4.0, 8.0]])
    """

    def __init__(self, backend: str, tau: float, params: Mapping[str, Any] | None = None) -> None:
        f = filters.make(backend, filters.constant_velocity(tau, ndim=M), **dict(params or {}))
        self.backend = backend
        self.engine: OnlineFilter = (OnlineBoxKF(f) if isinstance(f, BoxKF) else OnlineFIR(f) if isinstance(f, FIRFilter)
                                     else OnlineKalman(f))

    @property
    def n(self) -> int:
        """Live tracks."""
        return self.engine.n

    def predict(self) -> np.ndarray:
        """(n, 4) xywh: where each track is expected in the next frame (no state changes)."""
        return _xywh(self.engine.predict())

    def update(self, boxes: np.ndarray, births: np.ndarray | None = None) -> np.ndarray:
        """Advance every track by one frame with its detection ``boxes`` (n, 4) xywh, a NaN row for a track without
        one; returns the estimates (n, 4) xywh. ``births`` (k, 4) xywh: tracks that start in this frame (as
        :meth:`start` after the update; the Kalman back ends start them in the same call)."""
        born = None if births is None or len(births) == 0 else _cxcywh(births)
        return _xywh(self.engine.update(_cxcywh(boxes), born))

    def start(self, boxes: np.ndarray) -> np.ndarray:
        """Start k tracks at their first detections ``boxes`` (k, 4) xywh (appended as rows n … n + k − 1);
        returns their boxes."""
        if len(boxes):
            self.engine.start(_cxcywh(boxes))
        return np.asarray(boxes, dtype=float).reshape(-1, M).copy()

    def keep(self, index: np.ndarray) -> None:
        """Keep only the tracks ``index`` (an int array), in that order."""
        self.engine.keep(np.asarray(index, dtype=np.int64))

    def set_params(self, rows: np.ndarray, params: Mapping[str, Any]) -> None:
        """From the next frame on, the tracks ``rows`` run with ``params`` (``{name: scalar or (len(rows),)}``)."""
        self.engine.set_params(rows, params)
