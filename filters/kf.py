"""Standard Kalman filter ([PaleRamon-BBox] §"Kalman filter" / [PaleRamon-CMN] Algorithm 1; notes §1.0), batched.

Per coordinate: ``F = [[1, τ], [0, 1]]``, ``H = [1, 0]``, ``Q = σ_w² B Bᵀ`` with ``B = [τ²/2, τ]ᵀ``,
``R = σ_v²``.

Conventions
-----------
* Predict-first like filterpy: ``x0``/``P0`` are the prior *before* frame 0, and every frame runs
  predict then update, so with x0/P0 given the output equals filterpy's ``KalmanFilter`` loop
  ``predict(); update(y_n)`` (tested to 1e-9).
* ``x0=None``: the state is initialised at each channel's first finite measurement n0 as
  ``[y_{n0}, 0]`` with covariance ``P0`` (its per-coordinate blocks) or, for ``P0=None``,
  ``diag(σ_v², (10³ σ_v / τ)²)`` — position as measured, velocity effectively unknown (the next
  measurement sets it). Frames before n0 are NaN (no information yet); output is finite from n0 on.
* ``x0`` given, ``P0=None``: the prior covariance is that same diag(σ_v², (10³ σ_v / τ)²).
* NaN in y = missing: predict only (filterpy ``update(None)``).
* Output: posterior ``[positions, velocities]`` at every frame, float64.
* ``run_from(y, carry)`` continues a run from the posterior state and covariance a previous call ended in
  (:class:`bboxtune.filters.base.Carry`): the next frame is predict + update from there, with this call's σ_w, σ_v.

Speed: the gains are computed once per unique (σ_w, σ_v, missing pattern) and stop being recomputed once
they reach steady state (:mod:`bboxtune.filters.kalman_core`); all channels are then filtered together.

>>> import numpy as np
>>> from bboxtune import filters
>>> kf = filters.make("kf", filters.constant_velocity(0.05), sigma_w=50.0, sigma_v=4.0)
>>> kf.run(np.array([[1.0], [1.1], [np.nan], [1.3]])).round(3)
array([[1. , 0. ],
       [1.1, 2. ],
       [1.2, 2. ],
       [1.3, 2. ]])
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np

from bboxtune.filters import jit, kalman_kernels
from bboxtune.filters.base import AxisCarry, Filter
from bboxtune.filters.kalman_core import (
    UPDATE_Z,
    FramePrior,
    StepTables,
    channel_start,
    filter_channels,
    frame_kinds,
    plain_tables,
)
from bboxtune.filters.model import StateSpaceModel
from bboxtune.filters.validation import check_prior, check_sigma


class KF(FramePrior, Filter):
    """Kalman filter. Parameters: ``sigma_w`` (acceleration noise std, units/s², per track), ``sigma_v``
    (measurement noise std, units, per track), ``x0`` (K,) and ``P0`` (K, K) prior (see module docstring); valid
    ranges in :mod:`bboxtune.filters.validation` (σ within [1e-30, 1e30], P0 at most 1e8 σ_v² per coordinate in frame
    units)."""

    name: ClassVar[str] = "kf"
    DEFAULTS: ClassVar[dict[str, Any]] = {"sigma_w": 1.0, "sigma_v": 1.0, "x0": None, "P0": None}
    PER_TRACK: ClassVar[tuple[str, ...]] = ("sigma_w", "sigma_v")

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        sigma_v = check_sigma("sigma_v", params["sigma_v"])
        x0, P0 = check_prior(params["x0"], params["P0"], self.model.K, self.model.M, sigma_v, self.model.tau)
        return {"sigma_w": check_sigma("sigma_w", params["sigma_w"]), "sigma_v": sigma_v, "x0": x0, "P0": P0}

    def _run_axes_from(self, z: np.ndarray, params: dict[str, Any], start: AxisCarry | None,
                       u: np.ndarray | None) -> tuple[np.ndarray, AxisCarry]:
        axis = self.model.axis()
        var_v = params["sigma_v"] ** 2
        x_start, P_start, prior = channel_start(params["x0"], params["P0"], self.model.M, z.shape[0], var_v,
                                                axis.tau, start)
        finite = ~np.isnan(z)
        kinds = frame_kinds(finite, prior, measured=None if start is None else start.measured)
        row_params = np.stack([params["sigma_w"], params["sigma_v"]], axis=1)

        def tables(p: np.ndarray) -> StepTables:
            if jit.enabled():  # the same tables, compiled (~2 µs instead of ~40 µs for one row)
                F, BB, H, _ = axis_matrices(axis)
                return StepTables(*kalman_kernels.kf_tables(np.ascontiguousarray(p, dtype=np.float64), F, BB, H, UPDATE_Z))
            Q = (axis.B @ axis.B.T)[:, :, None] * p[:, 0] ** 2  # Q = σ_w² B Bᵀ
            return plain_tables(axis.F, Q, p[:, 1] ** 2, axis.H[0])  # R = σ_v²

        states, P_end = filter_channels(np.where(finite, z, 0.0), kinds, row_params, x_start, P_start,
                                        lambda p: TABLES.get(("kf", axis.F.tobytes(), axis.B.tobytes(), p), lambda: tables(p)))
        return states, AxisCarry(x=states[:, -1], P=P_end)


@lru_cache(maxsize=64)
def axis_matrices(axis: StateSpaceModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """F, B Bᵀ, H (the row) and H F⁻¹ of a two-state axis model, contiguous float64 (models are immutable)."""
    F, H = np.array(axis.F, dtype=np.float64), np.array(axis.H[0], dtype=np.float64)
    matrices = (F, axis.B @ axis.B.T, H, H @ np.linalg.inv(axis.F))
    for a in matrices:
        a.setflags(write=False)
    return matrices

class RecentTables:
    """The step tables of the last ``size`` keys of at most ``max_rows`` rows each: a tracker filters one frame per call
    with the same parameters, so the tables of a call are mostly those of the last one. The tables are made
    read-only."""

    def __init__(self, size: int, max_rows: int) -> None:
        self.size, self.max_rows = size, max_rows
        self._store: dict[tuple, StepTables] = {}

    def get(self, key: tuple, build: Callable[[], StepTables]) -> StepTables:
        """The tables of ``key`` = (…, row parameters (G, k)) — the last entry the array of the rows —, built by
        ``build()`` unless kept (always for more than ``max_rows`` rows)."""
        rows = key[-1]
        if len(rows) > self.max_rows:
            return build()
        key = (*key[:-1], rows.shape, rows.tobytes())
        tables = self._store.get(key)
        if tables is None:
            tables = build()
            for table in vars(tables).values():
                table.setflags(write=False)
            if len(self._store) >= self.size:
                del self._store[next(iter(self._store))]  # the oldest
            self._store[key] = tables
        return tables


TABLES = RecentTables(8, 4096)  # shared by kf and kf_cmn (the key names the back end)
