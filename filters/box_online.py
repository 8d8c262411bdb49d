"""The box Kalman filters of trackers (:class:`bboxtune.filters.bytetrack_kf.BoxKF`: ``bytetrack_kf``, ``sort_kf``) one
frame at a time over a changing set of tracks, as a tracker runs them: predict every track, update the matched ones,
start and end tracks between frames.

The steps are the batch recursion's own (:meth:`BoxKF.predict_state`, :func:`bboxtune.filters.box_state.update_state`,
:func:`~bboxtune.filters.box_state.initiate`), so a track's estimates equal ``run`` on its detections bit for bit
(tested), at a fraction of ``run_from``'s per-call cost. Boxes are (cx, cy, w, h) px; parameters per track.

>>> import numpy as np
>>> from bboxtune import filters
>>> kf = OnlineBoxKF(filters.make("bytetrack_kf", filters.constant_velocity(1 / 30, ndim=4)))
>>> kf.start(np.array([[50.0, 60.0, 20.0, 40.0]]))
>>> kf.update(np.array([[np.nan] * 4])).round(2).tolist()
[[50.0, 60.0, 20.0, 40.0]]
>>> kf.update(np.array([[52.0, 61.0, 22.0, 40.0]])).round(2).tolist()
[[51.85, 60.92, 20.06, 40.0]]
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from bboxtune.filters.base import Filter
from bboxtune.filters.box_state import HeightVariance, initiate, update_state
from bboxtune.filters.bytetrack_kf import GAP_DECAYS, BoxKF, M, check_boxes

# The noise table of n tracks, (NOISE_ROWS, n): per track the flattened (slope, offset) pairs of P₀ (2, 4), Q (2, 4)
# and R (4,) (HeightNoise.start, .process, .measurement), in that order.
_SHAPES = ((2, M), (2, M), (M,))
_BOUNDS = tuple(np.cumsum([0] + [math.prod(shape) for shape in _SHAPES for _part in ("slope", "offset")]).tolist())
NOISE_ROWS = _BOUNDS[-1]


class OnlineBoxKF:
    """``kf``'s recursion for n live tracks (columns of the state), each with its own parameters; new tracks start
    with ``kf``'s parameters.

    Per track it keeps the parameters (one column of a (p, n) array) and the noise they give (one column of the noise
    table): starting, ending and re-tuning tracks move or rebuild whole columns, and a track's column is the one
    ``kf._noise`` gives its parameters (tested against a full rebuild)."""

    def __init__(self, kf: BoxKF) -> None:
        if not isinstance(kf, BoxKF):
            raise TypeError(f"kf is a {type(kf).__name__}; allowed: a box filter of a tracker (bytetrack_kf, sort_kf)")
        check_no_gap_policy(kf.params)
        self.kf = kf
        self.X = np.empty((5, M, 0))  # [p, v, P01, P00, P11] per coordinate and track (bboxtune.filters.bytetrack_kf)
        self._names = tuple(kf.PER_TRACK)
        self._row = {name: i for i, name in enumerate(self._names)}
        self._values = np.empty((len(self._names), 0))  # the parameters of the live tracks, rows as _names
        self._table = np.empty((NOISE_ROWS, 0))  # their noise (the module's noise table)
        self._noise: tuple[HeightVariance, HeightVariance] | None = None  # (Q, R) of the live tracks: table views
        self._stock: tuple[np.ndarray, np.ndarray] | None = None  # (values, table) of one track with kf's parameters
        self._predicted: np.ndarray | None = None  # the state predicted by predict(), until the tracks or noise change

    @property
    def n(self) -> int:
        """Live tracks."""
        return self.X.shape[2]

    @property
    def params(self) -> dict[str, np.ndarray]:
        """The live tracks' parameters ``{name: (n,)}`` (copies)."""
        return {name: self._values[i].copy() for i, name in enumerate(self._names)}

    def _variances(self) -> tuple[HeightVariance, HeightVariance]:
        """(Q, R) of the live tracks."""
        if self._noise is None:
            self._noise = _table_variance(self._table, 1), _table_variance(self._table, 2)
        return self._noise

    def _changed(self) -> None:
        """The tracks or their noise changed: drop what was computed from them."""
        self._noise = self._predicted = None

    def _noise_table(self, values: np.ndarray) -> np.ndarray:
        """The noise table (NOISE_ROWS, k) of k tracks with the parameters ``values`` (p, k) (rows as ``_names``)."""
        k = values.shape[1]
        noise = self.kf._noise({name: values[i] for i, name in enumerate(self._names)})
        table = np.empty((NOISE_ROWS, k))
        for which, pair in enumerate((noise.start, noise.process, noise.measurement)):
            for part, array in enumerate(pair):  # slope, offset
                lo, hi = _BOUNDS[2 * which + part:2 * which + part + 2]
                table[lo:hi].reshape(*_SHAPES[which], k)[...] = array  # a view of the table: broadcast into it
        return table

    def _boxes(self, X: np.ndarray) -> np.ndarray:
        boxes = X[0].T.copy()
        self.kf._to_boxes(boxes)
        return boxes

    def predict(self) -> np.ndarray:
        """(n, 4) the boxes every track is expected at in the next frame (the state is not changed; the next
        :meth:`update` starts from this prediction instead of computing it again)."""
        X = self.X.copy()
        self.kf.predict_state(X, self._variances()[0])
        self._predicted = X
        return self._boxes(X)

    def update(self, boxes: np.ndarray, births: np.ndarray | None = None) -> np.ndarray:
        """One frame: every track predicts, those with a detection (a row of ``boxes`` (n, 4); NaN rows: none)
        update; returns the estimates (n, 4); then the tracks ``births`` (k, 4) start (:meth:`start`)."""
        estimates = self._update(boxes)
        if births is not None and len(births):
            self.start(births)
        return estimates

    def _update(self, boxes: np.ndarray) -> np.ndarray:
        boxes = np.asarray(boxes, dtype=float)
        if boxes.shape != (self.n, M):
            raise ValueError(f"boxes has shape {boxes.shape}; allowed ({self.n}, {M}): one row per live track")
        check_boxes(boxes[None])
        Q, R = self._variances()
        z = self.kf._measure(boxes.T[None])[0]  # (4, n)
        detected = ~np.isnan(z[0])
        if self._predicted is None:
            self.kf.predict_state(self.X, Q)
        else:  # predict()'s: the same steps on the same state and noise
            self.X, self._predicted = self._predicted, None
        update_state(self.X, np.where(detected, z, 0.0), R, None if detected.all() else detected.astype(float))
        return self._boxes(self.X)

    def start(self, boxes: np.ndarray, params: Mapping[str, Any] | None = None) -> None:
        """Start k tracks at their first detections ``boxes`` (k, 4) (appended as the last k columns), with
        ``params`` (``{name: scalar or (k,)}``; default: ``kf``'s)."""
        boxes = np.asarray(boxes, dtype=float)
        if boxes.ndim != 2 or boxes.shape[1] != M or np.isnan(boxes).any():
            raise ValueError(f"boxes has shape {boxes.shape} or NaN; allowed (k, {M}) detections")
        check_boxes(boxes[None])
        k = len(boxes)
        if params:
            check_no_gap_policy(params)
            given = type(self.kf)(self.kf.model, **{**self.kf.params, **params}).params
            values = np.array([np.broadcast_to(given[name], (k,)) for name in self._names], dtype=float).reshape(-1, k)
            table = self._noise_table(values)
        else:  # the template's noise, once per filter
            if self._stock is None:
                one = np.array([np.broadcast_to(self.kf.params[name], (1,)) for name in self._names],
                               dtype=float).reshape(-1, 1)
                self._stock = one, self._noise_table(one)
            values, table = (np.repeat(a, k, axis=1) for a in self._stock)
        X = np.full((5, M, k), np.nan)
        initiate(X, self.kf._measure(boxes.T[None])[0], _table_variance(table, 0), np.arange(k))
        self.X = np.concatenate([self.X, X], axis=2)
        self._values = np.concatenate([self._values, values], axis=1)
        self._table = np.concatenate([self._table, table], axis=1)
        self._changed()

    def keep(self, index: np.ndarray) -> None:
        """Keep only the tracks ``index`` (an int array), in that order."""
        self.X, self._values, self._table = self.X[:, :, index], self._values[:, index], self._table[:, index]
        self._changed()

    def set_params(self, rows: np.ndarray, params: Mapping[str, Any]) -> None:
        """The tracks ``rows`` use ``params`` (``{name: scalar or (len(rows),)}``, checked) from the next frame on.
        A box filter checks each parameter on its own (:meth:`BoxKF._validate`), so only those given are checked,
        without building a filter as :func:`track_params` does (a re-tuning tracker calls this every frame); only
        the noise of the tracks ``rows`` is rebuilt."""
        check_no_gap_policy(params)
        self.kf.check_names(params)
        values = self._values.copy()
        for name, value in self.kf._validate(dict(params)).items():
            values[self._row[name], rows] = value
        self._table[:, rows] = self._noise_table(values[:, rows])
        self._values = values
        self._changed()


def _table_variance(table: np.ndarray, which: int) -> HeightVariance:
    """P₀ (``which`` 0), Q (1) or R (2) of the tracks of a noise table (NOISE_ROWS, n), as views of it."""
    lo, mid, hi = _BOUNDS[2 * which:2 * which + 3]
    shape = (*_SHAPES[which], table.shape[1])
    return HeightVariance.of_full(table[lo:mid].reshape(shape), table[mid:hi].reshape(shape))


def check_no_gap_policy(params: Mapping[str, Any]) -> None:
    """ValueError if ``params`` set a gap policy (:mod:`bboxtune.filters.gap_output`): it shapes a smoothed track's
    output, while a tracker's filter predicts with its own model."""
    for name in GAP_DECAYS:
        if name in params and np.any(np.asarray(params[name]) != 1.0):
            value = np.asarray(params[name]).tolist()
            raise ValueError(f"{name}={value!r}: the gap policy shapes a smoothed track's output inside detection gaps "
                             "(run, positions); a tracker's filter predicts with its own model: allowed 1 (the default)")


def track_params(f: Filter, current: Mapping[str, np.ndarray], rows: np.ndarray, params: Mapping[str, Any]
                 ) -> dict[str, np.ndarray]:
    """Per-track parameters ``current`` (``{name: (n,)}``) with those of the tracks ``rows`` replaced by ``params``
    (``{name: scalar or (len(rows),)}``), checked by ``f``'s class as ``filters.make`` checks them."""
    return replaced(current, rows, type(f)(f.model, **{**f.params, **params}).params, params)


def replaced(current: Mapping[str, np.ndarray], rows: np.ndarray, given: Mapping[str, np.ndarray],
             names: Iterable[str] | None = None) -> dict[str, np.ndarray]:
    """Per-track parameters ``current`` (``{name: (n,)}``) with those ``names`` (default: all of ``given``) of the
    tracks ``rows`` set to the checked values ``given`` (``{name: scalar or (len(rows),)}``)."""
    updated = dict(current)
    for name in given if names is None else names:
        updated[name] = current[name].copy()
        updated[name][rows] = given[name]
    return updated
