"""The online engines (bboxtune.filters.online_carry) equal the reference carry engine (CarryFilter, one
``positions_from`` per frame) on a changing set of tracks: births, deaths, missing frames, new parameters mid-run,
with the compiled kernels and with the numpy references."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.agents.tracking.filter_bank import CarryFilter
from bboxtune.filters.box_online import OnlineBoxKF
from bboxtune.filters.bytetrack_kf import BoxKF
from bboxtune.filters.fir_core import FIRFilter
from bboxtune.filters.online_carry import OnlineKalman
from bboxtune.filters.online_fir import OnlineFIR

from ..kernel_modes import both

NOISE = {"sigma_w": 300.0, "sigma_v": 3.0}
CASES: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {  # back end: (parameters, a re-tuning mid-run)
    "kf": (NOISE, {"sigma_w": 80.0}),
    "kf_cmn": ({**NOISE, "psi": 0.3}, {"psi": 0.7, "sigma_v": 5.0}),
    "ukf": (NOISE, {"sigma_w": 80.0, "alpha": 0.5}),
    "ufir": ({"horizon": 6}, {"horizon": 9}),
    "ufir_cmn": ({"horizon": 6, "psi": 0.3}, {"horizon": 4, "psi": 0.6}),
    "ofir": ({**NOISE, "horizon": 6}, {"horizon": 8}),
    "oufir": ({**NOISE, "horizon": 6}, {"sigma_w": 50.0}),
    "fir": ({**NOISE, "horizon": 6}, {"horizon": 5}),
    "bytetrack_kf": ({}, {"std_weight_position": 0.2}),
    "sort_kf": ({}, {}),
}


def engine(f: filters.Filter) -> Any:
    return OnlineBoxKF(f) if isinstance(f, BoxKF) else OnlineFIR(f) if isinstance(f, FIRFilter) else OnlineKalman(f)


def scenario(first: Any, second: Any, retune: dict[str, Any], seed: int = 0, frames: int = 45) -> list[np.ndarray]:
    """Drive two engines through the same tracker-like run; every prediction and estimate of each, in order."""
    rng = np.random.default_rng(seed)
    outs: tuple[list[np.ndarray], list[np.ndarray]] = ([], [])
    centre = np.array([300.0, 200.0, 40.0, 90.0])
    for t in range(frames):
        n = first.n
        for e, out in zip((first, second), outs, strict=True):
            out.append(e.predict())
        boxes = centre + rng.normal(0, [3.0, 3.0, 0.5, 1.0], (n, 4)) + t * np.array([2.0, -1.0, 0.1, 0.2])
        boxes[rng.random(n) < 0.3] = np.nan  # tracks without a detection
        if t == 40:
            boxes[:] = np.nan  # a frame without any
        born = int(rng.integers(0, 3)) if t not in (30, 31) else 0
        new = centre + rng.normal(0, [20.0, 20.0, 2.0, 4.0], (born, 4))
        joint = t % 2 == 0  # the new tracks start in the update's call (as the tracker does), else after it
        for e, out in zip((first, second), outs, strict=True):
            out.append(e.update(boxes, new if joint else None))
        if t == 25 and n > 2 and retune:
            for e in (first, second):
                e.set_params(np.array([0, n - 1]), retune)
        if born and not joint:
            for e in (first, second):
                e.start(new)
        if t == 31:
            keep = np.empty(0, dtype=np.int64)  # every track ends: the next ones start afresh
        else:
            keep = np.flatnonzero(rng.random(first.n) > 0.1)
        for e in (first, second):
            e.keep(keep)
    return [np.concatenate(outs[0]), np.concatenate(outs[1])]


@pytest.mark.parametrize("name", sorted(CASES))
def test_online_engine_equals_the_carry_reference(name: str) -> None:
    params, retune = CASES[name]
    f = filters.make(name, filters.constant_velocity(1 / 14, ndim=4), **params)

    def run() -> list[np.ndarray]:
        return scenario(engine(f), CarryFilter(f), retune)

    for fast, reference in both(run):
        assert len(fast) > 150 and np.isfinite(reference).mean() > 0.9
        np.testing.assert_allclose(fast, reference, rtol=1e-9, atol=1e-9)
