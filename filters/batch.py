"""Batch runners: one back end over many tracks, each with its own parameter set and frame interval, in as few
filter calls as the tracks allow.

Batching across frame intervals happens here: a back end exact in frame units (``IN_FRAMES``: the FIR family, KF,
KF-CMN, the peer box filters bytetrack_kf and sort_kf, which work per frame anyway) runs every track at τ = 1 with
its parameters converted (:meth:`bboxtune.filters.base.Filter.params_in_frames`, the one definition of the conversion:
σ_w → σ_w τ², a prior's velocities × τ), so tracks of any τ share one cached
model and one call; the others (UKF) run at each track's τ. (A FIR filter built at another τ applies the same
conversion inside, so that its gains are cached once for all τ.) Position estimates are the same either way (to
round-off; tests/filters/
test_batch.py). Models are the constant-velocity models of :func:`bboxtune.filters.constant_velocity` (cached there).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from bboxtune.filters.base import Filter
from bboxtune.filters.model import StateSpaceModel, constant_velocity
from bboxtune.filters.registry import filter_class
from bboxtune.filters.threads import in_threads


def _run_intervals(cls: type[Filter], taus: np.ndarray, params: dict[str, np.ndarray]
                   ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The intervals to run at and the parameters to run with (module docstring)."""
    params = {k: np.asarray(v) for k, v in params.items()}
    if cls.IN_FRAMES:
        return np.ones_like(taus), cls.params_in_frames(params, taus)
    return taus, params


def candidate_positions(name: str, y: np.ndarray, tau: float, params: dict[str, np.ndarray]) -> np.ndarray:
    """Back end ``name`` on one track ``y`` (T, M) once per candidate: ``params`` maps the back end's parameter
    names to arrays (A,) (none: one candidate, A = 1, e.g. ``sort_kf``, which has no parameters). Returns the
    position estimates (A, T, M)."""
    cls = filter_class(name)
    n = len(next(iter(params.values()))) if params else 1
    tau_run, used = _run_intervals(cls, np.float64(tau), params)
    flt = cls(constant_velocity(float(tau_run), ndim=y.shape[-1]), **used)
    return flt.positions(np.broadcast_to(y, (n, *y.shape)))


def track_positions(name: str, ys: Sequence[np.ndarray], taus: Sequence[float],
                    params: dict[str, np.ndarray]) -> list[np.ndarray]:
    """Back end ``name`` on B tracks ``ys`` (T_b, M), each at its own interval ``taus[b]`` (s) with its own
    parameters ``params`` (arrays (B,)): tracks of equal length (and, outside frame units, equal τ) run in one
    call (many tracks: split over threads, a filter each, :func:`bboxtune.filters.threads.in_threads`, unless the back
    end splits its own work: ``Filter.SPLIT_TRACKS``). Returns the position estimates, B arrays (T_b, M), each equal to
    :func:`candidate_positions` on its track alone."""
    cls = filter_class(name)
    taus_run, used = _run_intervals(cls, np.asarray(taus, dtype=float), params)
    groups: dict[tuple[int, float], list[int]] = {}  # the tracks of each (length, interval), in track order
    for r, key in enumerate(zip([len(y) for y in ys], taus_run.tolist(), strict=True)):
        groups.setdefault(key, []).append(r)
    out: list[np.ndarray] = [np.empty(0)] * len(ys)
    for (_, tau), rows in sorted(groups.items()):
        model = constant_velocity(tau, ndim=ys[rows[0]].shape[-1])

        def run(part: slice, rows: list[int] = rows, model: StateSpaceModel = model) -> None:  # a filter per thread
            flt = cls(model, **{k: v[rows[part]] for k, v in used.items()})
            est = flt.positions(np.stack([ys[r] for r in rows[part]]))
            for i, r in enumerate(rows[part]):
                out[r] = est[i]

        if cls.SPLIT_TRACKS:
            in_threads(run, len(rows), len(ys[rows[0]]) * ys[rows[0]].shape[-1])
        else:
            run(slice(0, len(rows)))
    return out


def one_track_positions(name: str, y: np.ndarray, tau: float, params: dict[str, np.ndarray]) -> np.ndarray:
    """:func:`track_positions` of the one track ``y`` (T, M) with one parameter set ``params`` (arrays (1,)), bit for
    bit, with the configured filter cached per (back end, τ, parameter values): a tuner filters every track it sees
    with its rule, often the same parameters (bytetrack_kf's stock ones), and building the filter costs more than
    filtering one short track. Returns the position estimates (T, M)."""
    values = tuple((k, v.dtype.str, v.tobytes()) for k, v in params.items())
    return _one_track_filter(name, float(tau), y.shape[-1], values).positions(y[None])[0]


@lru_cache(maxsize=64)
def _one_track_filter(name: str, tau: float, n_coordinates: int, values: tuple[tuple[str, str, bytes], ...]) -> Filter:
    """The filter :func:`track_positions` builds for one track (the parameters as (name, dtype, bytes) of (1,) arrays)."""
    cls = filter_class(name)
    params = {k: np.frombuffer(raw, dtype=dtype).copy() for k, dtype, raw in values}
    taus_run, used = _run_intervals(cls, np.asarray([tau], dtype=float), params)
    return cls(constant_velocity(taus_run.tolist()[0], ndim=n_coordinates), **{k: v[[0]] for k, v in used.items()})
