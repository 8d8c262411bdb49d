"""The FIR family (``ufir``, ``ufir_cmn``, ``ofir``, ``oufir``, ``fir``) one frame at a time over a changing set of
tracks, as a tracker runs it (:mod:`bboxtune.filters.online_carry` has the interface and the Kalman family): the
measurement history is a buffer appended in place (the reference concatenates the whole history every frame), and
each frame filters its last max(N) + 1 frames as :func:`bboxtune.filters.history.continue_span` does, computing the
newest estimate only.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any, cast

import numpy as np

from bboxtune.filters import jit, online_fir_kernels
from bboxtune.filters.base import Filter
from bboxtune.filters.fir_core import FIRFilter
from bboxtune.filters.online_carry import M, PerTrack, channel_params, check_births, check_rows

GAIN_KINDS = 4096  # window kinds (gain parameters, missing pattern) whose gains an OnlineFIR keeps


class OnlineFIR(PerTrack):
    """A FIR-family back end ``f`` (``ufir``, ``ufir_cmn``, ``ofir``, ``oufir``, ``fir``; a 4-coordinate model) for n
    live tracks, its measurement history in a buffer that grows by doubling (the reference keeps every frame too:
    a later ``set_params`` may lengthen the horizon). Each frame computes the newest estimate only
    (:func:`newest_positions`), on the frames the reference filters."""

    def __init__(self, f: Filter) -> None:
        if not isinstance(f, FIRFilter):
            raise TypeError(f"f is a {type(f).__name__}; allowed: a FIR-family back end (OnlineKalman runs the others)")
        super().__init__(f)
        self._y = np.full((0, 16, M), np.nan)  # (n, capacity, 4): frames 0 … length − 1 are the history
        self._length = 0  # frames of history (0: none yet, as after every track ended)
        self._windows: WindowGroups | None = None  # the live tracks' gain groups (when their parameters change)
        self._gains: dict[tuple, np.ndarray] = {}  # WindowGroups.gains
        self._predicted: np.ndarray | None = None  # (n, 4) the next frame's estimates without detections, if known
        self._predicted_reach = 0  # the reach they were computed with
        self._template: tuple[tuple, int] | None = None  # template_window(f), once
        self._reach_all: int | None = None  # _reach of every live track (when their parameters change)

    def _changed(self) -> None:
        super()._changed()
        self._windows = self._predicted = self._reach_all = None

    def _groups(self) -> WindowGroups:
        if self._windows is None:
            self._windows = WindowGroups(cast(FIRFilter, self.f), self._channel_params(), self._gains)
        return self._windows

    def _reach(self, rows: np.ndarray | None = None) -> int:
        """History frames a continued run of the tracks ``rows`` (default: all live ones) reads
        (:func:`bboxtune.filters.history.continue_span`)."""
        if rows is not None:
            return int(np.max(self.params["horizon"][rows])) + 1
        if self._reach_all is None:
            self._reach_all = int(np.max(self.params["horizon"])) + 1
        return self._reach_all

    def _span(self, rows: int, last: int, reach: int) -> np.ndarray:
        """Channels (rows · 4, S) of the first ``rows`` tracks: frame ``last`` led by the history frames before it that a
        continued run reads (at most ``reach``)."""
        lead = min(last, reach)
        return self._y[:rows, last - lead:last + 1].transpose(0, 2, 1).reshape(rows * M, lead + 1)

    def _grow(self) -> None:
        """Room for two more frames in the buffer (the next one and the one after)."""
        if self._length + 2 > self._y.shape[1]:
            self._y = np.concatenate([self._y, np.full_like(self._y, np.nan)], axis=1)

    def predict(self) -> np.ndarray:
        """(n, 4) the estimate of every track at the next frame without a detection (the history is not changed);
        computed with the last update where it could be (the same frames, parameters and gains)."""
        if self._n == 0:
            return np.empty((0, M))
        if self._predicted is None:
            self._grow()
            self._y[:, self._length] = np.nan
            span = self._span(self._n, self._length, self._reach())
            self._predicted = self._groups().newest_positions(span).reshape(self._n, M)
            self._predicted_reach = self._reach()
        return self._predicted.copy()

    def update(self, boxes: np.ndarray, births: np.ndarray | None = None) -> np.ndarray:
        """One frame: each track's detection (a row of ``boxes`` (n, 4); NaN rows: none) joins its history; returns
        the estimates (n, 4); then the tracks ``births`` (k, 4) start (:meth:`start`). The next frame's predictions
        are computed in the same pass where their window spans as many frames as the update's (from the
        ``reach``-th frame of the history on)."""
        boxes = check_rows(boxes, self._n)
        n_old, last = self._n, self._length
        if n_old == 0:
            if births is not None:
                self.start(births)
            return np.empty((0, M))
        self._grow()
        self._y[:, last] = boxes
        reach = self._reach()
        self._length += 1
        if births is not None:
            self.start(births)
        windows, n, reach_next = self._groups(), self._n, self._reach()
        self._y[:, last + 1] = np.nan  # the next frame, without detections
        now, ahead = self._span(n_old, last, reach), self._span(n, last + 1, reach_next)
        old = np.arange(n_old * M)
        if now.shape[1] == ahead.shape[1]:
            both = windows.newest_positions(np.concatenate([now, ahead]), np.concatenate([old, np.arange(n * M)]))
            estimates, predicted = both[:n_old * M], both[n_old * M:]
        else:
            estimates, predicted = windows.newest_positions(now, old), windows.newest_positions(ahead)
        self._predicted, self._predicted_reach = predicted.reshape(n, M), reach_next
        return estimates.reshape(n_old, M)

    def start(self, boxes: np.ndarray, params: Mapping[str, Any] | None = None) -> None:
        """Start k tracks at their first detections ``boxes`` (k, 4) (appended as the last k rows; their history is
        that frame, led by missing frames back to the oldest track's first), with ``params`` (``{name: scalar or
        (k,)}``; default: the template's)."""
        boxes = check_births(boxes)
        k = len(boxes)
        if k == 0:
            return
        windows = self._windows
        self._add_params(k, params)
        if windows is not None and not params:  # the template's parameters: the live tracks' groups, extended
            if self._template is None:
                self._template = template_window(cast(FIRFilter, self.f))
            self._windows = windows.extended(k * M, *self._template)
        self._length = max(self._length, 1)
        fresh = np.full((k, self._y.shape[1], M), np.nan)
        fresh[:, self._length - 1] = boxes
        self._y = np.concatenate([self._y, fresh])
        self._n += k

    def keep(self, index: np.ndarray) -> None:
        """Keep only the tracks ``index`` (an int array), in that order (the history starts over when none is kept)."""
        index = np.asarray(index, dtype=np.int64)
        predicted = self._predicted
        if predicted is not None and (len(index) == 0 or self._reach(index) != self._predicted_reach):
            predicted = None  # fewer frames in the span now
        self._y = self._y[index]
        if len(index) == 0:
            self._length = 0
        windows = self._windows
        self._keep_params(index)
        self._predicted = None if predicted is None else predicted[index]
        if windows is not None and len(index):  # the kept tracks' groups (the groups themselves unchanged)
            self._windows = windows.taken((index[:, None] * M + np.arange(M)).ravel())


class WindowGroups:
    """The FIR windows of the channels of back end ``f`` with parameters ``params`` (:func:`channel_params`), in
    frame units (:meth:`FIRFilter._run_axes`): every channel's gain group, window length and gain parameters.
    ``gains`` keeps each window kind's position gain (NaN: the window does not determine the state) across
    instances: ``{(gain parameters, window length, mask bits): (L,)}``."""

    def __init__(self, f: FIRFilter, params: dict[str, Any], gains: dict[tuple, np.ndarray]) -> None:
        self.f = f._in_frames if f.model.tau != 1.0 else f  # the gains of the frame-unit twin, as _run_axes uses
        self.group, self.gparams = self.f._groups(f.params_in_frames(params, f.model.tau))
        self.length = (self.gparams["horizon"] + f.EXTRA_SAMPLES)[self.group]  # (C,) full window of each channel
        self.group_keys = list(zip(*(v.tolist() for v in self.gparams.values()), strict=True))
        self.gains = gains
        self.rows: dict[tuple[int, int], np.ndarray] = {}  # {(L, window code): gain row (L,)}, this group numbering

    def extended(self, channels: int, key: tuple, length: int) -> WindowGroups | None:
        """These windows and ``channels`` more of gain parameters ``key`` (frame units) and window ``length``, or None
        where ``key`` is not one of the groups (then build the groups anew)."""
        if key not in self.group_keys:
            return None
        out = copy.copy(self)
        out.group = np.concatenate([self.group, np.full(channels, self.group_keys.index(key), dtype=self.group.dtype)])
        out.length = np.concatenate([self.length, np.full(channels, length, dtype=self.length.dtype)])
        return out

    def taken(self, channels: np.ndarray) -> WindowGroups:
        """These windows for the channels ``channels`` (an int array) only, in that order."""
        out = copy.copy(self)
        out.group, out.length = self.group[channels], self.length[channels]
        return out

    def newest_positions(self, z: np.ndarray, channels: np.ndarray | None = None) -> np.ndarray:
        """The position estimate (C,) at the last frame of channels ``z`` (C, S) (frame 0 = each one's first; of the
        channels ``channels`` (C,), default all): what ``f.positions`` gives there — the full window, the start-up
        window (frames 0 … S − 1) or the window with its missing samples dropped, by the same gains; the latest
        measurement where the window does not determine the state (NaN before any). Compiled kernels
        (:mod:`bboxtune.filters.online_fir_kernels`) where :func:`bboxtune.filters.jit.enabled`, else numpy."""
        S = z.shape[1]
        group = self.group if channels is None else self.group[channels]
        lengths = np.minimum(self.length if channels is None else self.length[channels], S)  # shorter: start-up
        L = int(lengths.max())
        window = z[:, S - L:]
        n_groups = len(self.group_keys)
        compiled = jit.enabled()
        if 2 * L + n_groups.bit_length() <= 62:  # a window kind per (group, length, mask) in 63 bits
            if compiled:
                codes, first, kind = online_fir_kernels.window_kinds(window, lengths, group, n_groups)
            else:
                masks = ~np.isnan(window) & (np.arange(L) >= L - lengths[:, None])  # right-aligned windows
                bits = np.int64(1) << np.arange(L, dtype=np.int64)
                codes = ((masks @ bits) + (lengths.astype(np.int64) << L)) * n_groups + group
                codes, first, kind = np.unique(codes, return_index=True, return_inverse=True)
            if len(self.rows) >= GAIN_KINDS:
                self.rows.clear()
            rows = []
            for code, i in zip(codes.tolist(), first.tolist(), strict=True):
                row = self.rows.get((L, code))
                if row is None:
                    row = self.rows[(L, code)] = self._gain_row(window[i], int(lengths[i]), int(group[i]))
                rows.append(row)
            W = np.array(rows)
        else:
            masks = ~np.isnan(window) & (np.arange(L) >= L - lengths[:, None])
            _, first, kind = np.unique(np.column_stack([group, lengths, np.packbits(masks, axis=1)]), axis=0,
                                       return_index=True, return_inverse=True)
            W = np.array([self._gain_row(window[i], int(lengths[i]), int(group[i])) for i in first.tolist()])
        kind = kind.reshape(-1)
        if compiled:
            out, failed_at = online_fir_kernels.newest_estimates(W, kind, window, lengths, z)
            if failed_at >= 0:
                raise FloatingPointError(self._no_estimate(failed_at))
            return out
        W = W[kind]
        masks = ~np.isnan(window) & (np.arange(L) >= L - lengths[:, None])
        out = np.einsum("pl,pl->p", W, np.where(masks, window, 0.0))
        failed = ~np.isnan(W[:, -1]) & np.isnan(out)
        if failed.any():
            raise FloatingPointError(self._no_estimate(int(np.argmax(failed))))
        held = np.isnan(out)  # undetermined windows: the latest measurement of the span (NaN before any)
        if held.any():
            valid = ~np.isnan(z[held])
            last = S - 1 - np.argmax(valid[:, ::-1], axis=1)
            out[held] = np.where(valid.any(axis=1), z[held, last], np.nan)
        return out

    def _no_estimate(self, channel: int) -> str:
        return (f"{self.f.name}: no finite estimate for channel {channel} although its window determines the state — "
                "please report this input")

    def _gain_row(self, window: np.ndarray, length: int, group: int) -> np.ndarray:
        """The gain row (L,) of a channel's ``window`` (L,) (right-aligned, its last ``length`` samples; zeros before)
        of gain group ``group``."""
        row = np.zeros(len(window))
        start = len(window) - length
        row[start:] = self._gain(~np.isnan(window[start:]), group)
        return row

    def _gain(self, mask: np.ndarray, group: int) -> np.ndarray:
        """The position gain (L,) of window ``mask`` (L,) of gain group ``group``, NaN where it does not determine the
        state (:meth:`FIRFilter.observable`); the back end's cached gain (``_lookup``), kept in ``gains``."""
        key = (self.group_keys[group], mask.tobytes())
        gain = self.gains.get(key)
        if gain is None:
            if len(self.gains) >= GAIN_KINDS:
                self.gains.clear()
            gp = {k: v[group:group + 1] for k, v in self.gparams.items()}
            gain = np.full(len(mask), np.nan)
            if self.f.observable(mask[None], gp)[0]:
                gain = self.f._lookup(mask[None], gp)[0, 0]
            self.gains[key] = gain
        return gain


def template_window(f: FIRFilter) -> tuple[tuple, int]:
    """The gain parameters (frame units, as :class:`WindowGroups` keys them) and the window length of ``f``'s own
    parameters."""
    one = {k: np.atleast_1d(np.asarray(f.params[k], dtype=float)) for k in f.PER_TRACK}
    twin = f._in_frames if f.model.tau != 1.0 else f
    _, gparams = twin._groups(f.params_in_frames(channel_params(f, one), f.model.tau))
    return next(zip(*(v.tolist() for v in gparams.values()), strict=True)), int(gparams["horizon"][0]) + f.EXTRA_SAMPLES
