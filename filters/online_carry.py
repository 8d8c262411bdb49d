"""Any back end of :mod:`bboxtune.filters` one frame at a time over a changing set of tracks, as a tracker runs it:
predict every track, update the matched ones, start and end tracks between frames, re-tune some.

The reference is a carry (:meth:`bboxtune.filters.base.Filter.positions_from` once per frame, with a filter built
and validated for the live tracks' parameters every call, as ``bboxtune.agents.tracking.filter_bank.CarryFilter``
runs it). The engines here compute the same estimates with the back end's own code on the same numbers, minus the
per-frame bookkeeping:

* :class:`OnlineKalman` (the Kalman family: ``kf``, ``kf_cmn``, ``ukf``): the carried state stays split into
  channels (:class:`bboxtune.filters.base.AxisCarry`) between frames, and each frame is one call of the back end's
  ``_run_axes_from`` on one frame — no carry validation, no split / merge, no new filter;
* :class:`bboxtune.filters.online_fir.OnlineFIR` (the FIR family: ``ufir``, ``ufir_cmn``, ``ofir``, ``oufir``,
  ``fir``): the measurement history is a buffer appended in place (the reference concatenates the whole history
  every frame), and each frame filters its last max(N) + 1 frames as :func:`bboxtune.filters.history.continue_span`
  does.

Both build and validate the filter of the live tracks' parameters only when ``start``, ``keep`` or ``set_params``
change them. Boxes are (cx, cy, w, h) (any 4-coordinate model); parameters are the back end's ``PER_TRACK`` ones,
per track; new tracks start with the template filter's.

>>> import numpy as np
>>> from bboxtune import filters
>>> kf = OnlineKalman(filters.make("kf", filters.constant_velocity(1 / 30, ndim=4), sigma_w=300.0, sigma_v=3.0))
>>> kf.start(np.array([[50.0, 60.0, 20.0, 40.0]]))
>>> kf.update(np.array([[52.0, 61.0, 20.0, 40.0]])).round(2).tolist()
[[52.0, 61.0, 20.0, 40.0]]
>>> kf.predict().round(2).tolist()
[[54.0, 62.0, 20.0, 40.0]]
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, cast

import numpy as np

from bboxtune.filters.base import AxisCarry, Filter, measurement_history
from bboxtune.filters.box_online import track_params
from bboxtune.filters.fir_core import FIRFilter
from bboxtune.filters.validation import check_values

M = 4  # measured coordinates of a box: cx, cy, w, h


def check_rows(boxes: np.ndarray, n: int) -> np.ndarray:
    """``boxes`` as a float (n, 4) array (one row per live track), else a ValueError naming it."""
    boxes = np.asarray(boxes, dtype=float)
    if boxes.shape != (n, M):
        raise ValueError(f"boxes has shape {boxes.shape}; allowed ({n}, {M}): one row per live track")
    check_values("boxes", boxes)
    return boxes


def check_births(boxes: np.ndarray) -> np.ndarray:
    """The first detections of new tracks as a float (k, 4) array without NaN, else a ValueError naming them."""
    boxes = np.asarray(boxes, dtype=float)
    if boxes.ndim != 2 or boxes.shape[1] != M or np.isnan(boxes).any():
        raise ValueError(f"boxes has shape {boxes.shape} or NaN; allowed (k, {M}) detections")
    check_values("boxes", boxes)
    return boxes


class PerTrack:
    """The per-track parameters of the live tracks, each validated where it was set (the template ``f``'s, or
    :func:`track_params`), and their per-channel form (built when they change)."""

    def __init__(self, f: Filter) -> None:
        if f.model.M != M:
            raise ValueError(f"f's model measures {f.model.M} coordinate(s); allowed {M} (cx, cy, w, h)")
        self.f = f
        self.params: dict[str, np.ndarray] = {name: np.empty(0) for name in f.PER_TRACK}
        self._by_channel: dict[str, Any] | None = None  # the parameters per channel (channel_params)
        self._n = 0

    @property
    def n(self) -> int:
        """Live tracks."""
        return self._n

    def _channel_params(self) -> dict[str, Any]:
        if self._by_channel is None:
            self._by_channel = channel_params(self.f, self.params)
        return self._by_channel

    def _changed(self) -> None:
        self._by_channel = None

    def _add_params(self, k: int, params: Mapping[str, Any] | None) -> None:
        """Append the parameters of k new tracks: the template's, with ``params`` (checked) where given."""
        given = self.f.params if not params else type(self.f)(self.f.model, **{**self.f.params, **params}).params
        self.params = {name: np.concatenate([self.params[name], np.full(k, given[name], dtype=float)]) for name in self.params}
        self._changed()

    def _keep_params(self, index: np.ndarray) -> None:
        self.params = {name: values[index] for name, values in self.params.items()}
        self._changed()
        self._n = len(index)

    def set_params(self, rows: np.ndarray, params: Mapping[str, Any]) -> None:
        """The tracks ``rows`` use ``params`` (``{name: scalar or (len(rows),)}``, checked) from the next frame on."""
        self.params = track_params(self.f, self.params, rows, params)
        self._changed()


def channel_params(f: Filter, per_track: Mapping[str, np.ndarray]) -> dict[str, Any]:
    """The parameters of ``f``'s ``_run_axes_from`` / ``_run_axes`` for tracks with ``per_track`` parameters
    (``{name: (n,)}``, validated): per channel (n·4,), track-major, with ``f``'s shared ones (what
    :meth:`bboxtune.filters.base.Filter._chunks` hands them)."""
    return {**{k: v for k, v in f.params.items() if k not in per_track},
            **{k: np.repeat(v, M) for k, v in per_track.items()}}


class OnlineKalman(PerTrack):
    """A Kalman-family back end ``f`` (``kf``, ``kf_cmn``, ``ukf``; a 4-coordinate model) for n live tracks, its
    carry kept in channels (channel c = track c // 4, coordinate c % 4)."""

    def __init__(self, f: Filter) -> None:
        if isinstance(f, FIRFilter):
            raise TypeError(f"f is a {type(f).__name__}; allowed: a Kalman-family back end (OnlineFIR runs the FIR family)")
        super().__init__(f)
        self._carry: AxisCarry | None = None  # every field set, per channel

    def _step(self, z: np.ndarray) -> tuple[np.ndarray, AxisCarry]:
        """One frame ``z`` (C, 1) of every channel from the carry: positions (C,) and the carry after it."""
        f, params, start = self.f, self._channel_params(), self._carry
        axes, end = f._run_axes_from(z, params, start, None)
        if not np.isfinite(axes).all():  # NaN is allowed only before a channel's first measurement
            f._check_finite(axes, z, slice(0, self._n), params)
        return axes[:, 0, 0], AxisCarry(x=end.x, P=end.P, c=end.c, P_c=end.P_c, **next_history(z[:, 0], start))

    def predict(self) -> np.ndarray:
        """(n, 4) the boxes every track is expected at in the next frame (the state is not changed)."""
        if self._n == 0 or self._carry is None:
            return np.empty((0, M))
        F = self.f.model.axis().F  # a frame without a measurement is predict-only in every Kalman back end: x = F x
        x = self._carry.x
        return (F[0, 0] * x[:, 0] + F[0, 1] * x[:, 1]).reshape(self._n, M)

    def update(self, boxes: np.ndarray, births: np.ndarray | None = None) -> np.ndarray:
        """One frame: every track predicts, those with a detection (a row of ``boxes`` (n, 4); NaN rows: none)
        update; returns the estimates (n, 4). ``births`` (k, 4): tracks that start in this frame, as :meth:`start`
        after the update would start them, in the same call of the back end (their channels have not started:
        the back end starts them as a run without a carry does)."""
        boxes = check_rows(boxes, self._n)
        n = self._n
        k = 0 if births is None else len(births)
        if k:
            births = check_births(cast(np.ndarray, births))
            self._add_params(k, None)
            fresh = not_started(k * M, self.f.camera_coordinates * k)
            self._carry = fresh if self._carry is None else _join(self._carry, fresh)
            self._n += k
            boxes = np.concatenate([boxes, births])
        if self._n == 0:
            return np.empty((0, M))
        positions, self._carry = self._step(boxes.reshape(-1, 1))
        return positions[:n * M].reshape(n, M)

    def start(self, boxes: np.ndarray, params: Mapping[str, Any] | None = None) -> None:
        """Start k tracks at their first detections ``boxes`` (k, 4) (appended as the last k rows), with ``params``
        (``{name: scalar or (k,)}``; default: the template's)."""
        boxes = check_births(boxes)
        k = len(boxes)
        if k == 0:
            return
        self._add_params(k, params)
        z, run_params = boxes.reshape(-1, 1), {**self._channel_params()}
        run_params.update({name: v[-k * M:] for name, v in run_params.items() if name in self.params})
        axes, end = self.f._run_axes_from(z, run_params, None, None)
        self.f._check_finite(axes, z, slice(self._n, self._n + k), run_params)
        fresh = AxisCarry(x=end.x, P=end.P, c=end.c, P_c=end.P_c, **measurement_history(z, None))
        self._carry = fresh if self._carry is None else _join(self._carry, fresh)
        self._n += k

    def keep(self, index: np.ndarray) -> None:
        """Keep only the tracks ``index`` (an int array), in that order."""
        index = np.asarray(index, dtype=np.int64)
        channels = (index[:, None] * M + np.arange(M)).ravel()
        if self._carry is not None:
            self._carry = None if len(index) == 0 else _take(self._carry, channels, index)
        self._keep_params(index)


def not_started(channels: int, camera_channels: int) -> AxisCarry:
    """The carry of ``channels`` channels that have not started (no measurement yet: a back end starts them as a run
    without a carry does), ``camera_channels`` of them with camera states."""
    nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    return AxisCarry(x=nan(channels, 2), P=nan(channels, 2, 2), c=nan(camera_channels) if camera_channels else None,
                     P_c=nan(camera_channels, 3) if camera_channels else None, y_last=nan(channels),
                     measured=np.zeros(channels, bool), missed=np.zeros(channels, np.int64))


def next_history(z: np.ndarray, start: AxisCarry | None) -> dict[str, np.ndarray]:
    """:func:`bboxtune.filters.base.measurement_history` of one frame ``z`` (C,) after ``start``: the same values."""
    if start is None:
        return measurement_history(z[:, None], None)
    finite = ~np.isnan(z)
    y_before, missed = cast(np.ndarray, start.y_last), cast(np.ndarray, start.missed)  # set by every engine step
    return {"y_last": np.where(finite, z, y_before), "missed": np.where(finite, 0, np.where(np.isnan(y_before), 0, missed + 1)),
            "measured": cast(np.ndarray, start.measured) | finite}


def _join(first: AxisCarry, second: AxisCarry) -> AxisCarry:
    """The channels of ``first`` followed by those of ``second``."""
    parts = {name: (getattr(first, name), getattr(second, name)) for name in AxisCarry.__dataclass_fields__}
    joined: dict[str, Any] = {name: None if a is None else np.concatenate([a, b]) for name, (a, b) in parts.items()}
    return AxisCarry(**joined)


def _take(carry: AxisCarry, channels: np.ndarray, tracks: np.ndarray) -> AxisCarry:
    """The channels ``channels`` of ``carry`` (its camera states, one block per track: of ``tracks``)."""
    out: dict[str, Any] = {name: None if getattr(carry, name) is None else getattr(carry, name)[channels]
                           for name in AxisCarry.__dataclass_fields__}
    for name in ("c", "P_c"):  # track-major camera channels: n_c per track
        value = getattr(carry, name)
        if value is not None:
            per_track = len(value) // (len(carry.x) // M)
            out[name] = value.reshape(-1, per_track, *value.shape[1:])[tracks].reshape(-1, *value.shape[1:])
    return AxisCarry(**out)
