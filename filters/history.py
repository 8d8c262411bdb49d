"""The FIR family's :meth:`~bboxtune.filters.base.Filter.run_from`: its carry is the measurement history.

A FIR estimate at frame n depends only on the measurements of its window (the last N + ``EXTRA_SAMPLES`` frames),
so continuing a run needs no filter state, only the recent measurements. :class:`History` keeps every
measurement seen so far (the next call may use a longer horizon); a continued run filters the last
max(N) + 1 frames of it followed by the new frames and returns the new frames' estimates.

Equality with :meth:`~bboxtune.filters.base.Filter.run` on the whole track: exact (to round-off) wherever every window
is the full horizon or starts at the track's first frame — the start-up windows are the same because the run
reaches back to the first frame while the history is short. One exception: after a gap longer than the
horizon a FIR run holds the last estimate made before the gap, while a run continued inside such a gap finds
no measurement in the frames it reaches back to and has no estimate (NaN) until the gap ends; from the next
measurement on both are equal again (tests/filters/test_history.py checks both cases).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class History:
    """The measurements (B, H, M) a FIR run has seen so far (NaN = missing), read-only (a writeable array is
    copied, a read-only one kept as it is); H = 0 before the first frame. Like :class:`~bboxtune.filters.base.Carry`
    it can be sliced per track and repeated
    for candidates."""

    y: np.ndarray

    def __post_init__(self) -> None:
        arr = np.asarray(self.y, dtype=float)
        if arr.ndim != 3:
            raise ValueError(f"History.y has shape {arr.shape}; allowed (B, H, M)")
        if arr.flags.writeable:
            arr = arr.copy()
            arr.setflags(write=False)
        object.__setattr__(self, "y", arr)

    def slice(self, rows: slice) -> History:
        """The history of tracks ``rows``."""
        return History(self.y[rows])

    def take(self, index: np.ndarray) -> History:
        """The history of the tracks ``index`` (an int array, in its order)."""
        return History(self.y[index])

    def repeat(self, n: int) -> History:
        """This one-track history (B = 1) for ``n`` tracks (e.g. ``n`` candidate parameter sets): a broadcast view,
        not ``n`` copies."""
        if self.y.shape[0] != 1:
            raise ValueError(f"repeat needs a one-track history; History.y has shape {self.y.shape}, allowed (1, H, M)")
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n={n!r}; allowed: an integer >= 1")
        return History(np.broadcast_to(self.y, (int(n), *self.y.shape[1:])))


def continue_span(y: np.ndarray, history: History | None, reach: int) -> tuple[np.ndarray, int, History]:
    """The measurements to filter for new frames ``y`` (B, T, M) after ``history``: the last ``reach`` frames
    of the history, then ``y``; how many history frames lead them (the estimates to drop); the history after
    ``y``. A history must have the batch size and coordinates of ``y``."""
    if history is None:
        past = np.empty((y.shape[0], 0, y.shape[2]))
    else:
        past = history.y
        if past.shape[0] != y.shape[0] or past.shape[2] != y.shape[2]:
            raise ValueError(f"carry holds {past.shape[0]} track(s) of {past.shape[2]} coordinate(s); y has "
                             f"{y.shape[0]} of {y.shape[2]}: allowed the same (History.repeat for candidates)")
    full = np.concatenate([past, y], axis=1)
    full.setflags(write=False)  # new and read-only: History keeps it without a copy
    lead = min(past.shape[1], reach)
    return full[:, past.shape[1] - lead:], lead, History(full)
