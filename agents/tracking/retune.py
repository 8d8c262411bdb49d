"""Causal per-track re-tuning inside a tracker: a track's filter parameters are chosen from its own past only.

Every ``window`` frames of a track's life, from its ``first``-th frame on, a trained tuner
(:class:`bboxtune.agents.smoothing.tuner.Tuner`, e.g. the pretrained ``mot15_det``) sees the track's last
``history`` frames of matched detections (NaN rows for frames without one; never a future frame, never a ground
truth) and chooses the back end's parameters, which the track's filter uses from the next frame on — as
``bboxtune/FilterRetune-v0`` re-tunes every W frames. Before its first re-tune a track runs with the bank's
parameters (the stock values). A track with fewer than two matched detections in view keeps its parameters.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from bboxtune.agents.smoothing.tuner import MIN_FRAMES, MIN_MEASURED, check_tau

if TYPE_CHECKING:
    from bboxtune.agents.smoothing.tuner import Tuner
    from bboxtune.agents.tracking.filter_bank import FilterBank


class CausalRetune:
    """Re-tunes the live tracks of a tracker with ``tuner`` (frame interval ``tau`` s) every ``window`` frames
    from a track's ``first`` frame on, seeing at most its last ``history`` frames."""

    def __init__(self, tuner: Tuner, tau: float, window: int = 10, history: int = 100, first: int = MIN_FRAMES) -> None:
        for name, value, low in (("window", window, 1), ("history", history, MIN_FRAMES), ("first", first, MIN_FRAMES)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= 10**6:
                raise ValueError(f"{name}={value!r}; allowed: an integer {low}..1000000")
        self.tuner, self.tau = tuner, check_tau(tau)
        self.window, self.history, self.first = int(window), int(history), int(first)
        self._y = np.full((0, self.history, 4), np.nan)  # the last `history` frames of each live track, xywh
        self._age = np.empty(0, dtype=np.int64)  # frames each track has lived
        self.calls = 0  # tracks re-tuned so far

    def start(self, boxes: np.ndarray) -> None:
        """New tracks at their first detections ``boxes`` (k, 4) xywh (appended, as the filter bank's rows)."""
        fresh = np.full((len(boxes), self.history, 4), np.nan)
        fresh[:, -1] = boxes
        self._y = np.concatenate([self._y, fresh])
        self._age = np.concatenate([self._age, np.ones(len(boxes), dtype=np.int64)])

    def observe(self, measured: np.ndarray) -> None:
        """One more frame of every live track: its matched detection (n, 4) xywh, NaN rows for none."""
        self._y[:, :-1] = self._y[:, 1:]
        self._y[:, -1] = measured
        self._age += 1

    def keep(self, index: np.ndarray) -> None:
        """Keep only the tracks ``index``, in that order."""
        self._y, self._age = self._y[index], self._age[index]

    def retune(self, bank: FilterBank) -> None:
        """Set new parameters in ``bank`` for every track due (its age is ``first`` + a multiple of ``window``)."""
        due = np.flatnonzero((self._age >= self.first) & ((self._age - self.first) % self.window == 0))
        chosen: list[int] = []
        values: dict[str, list[float]] = {name: [] for name in self.tuner.parameters}
        for row in due:
            seen = self._y[row, -min(int(self._age[row]), self.history):]
            if int(np.isfinite(seen[:, 0]).sum()) < MIN_MEASURED:
                continue
            params = self.tuner.tune(seen, self.tau)
            chosen.append(int(row))
            for name in values:
                values[name].append(float(params[name]))
        if chosen:
            bank.set_params(np.array(chosen), {name: np.array(v) for name, v in values.items()})
            self.calls += len(chosen)
