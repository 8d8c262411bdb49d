"""The FIR family's compiled kernels against their numpy references (``jit.ENABLED`` on vs off), property-tested on
random tracks: several batch sizes, very short tracks (T < N), horizons from 2 to beyond T, ψ in [0, 1), and missing
frames isolated (5 %) or in runs (40–60 %)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters import jit, threads, window_scan_kernels
from bboxtune.filters.ufir import ufir_iterative
from tests.kernel_modes import counting_splits

TAU = 1 / 30
RTOL = 1e-9


@contextmanager
def kernels(on: bool) -> Iterator[None]:
    saved = jit.ENABLED
    jit.ENABLED = on
    try:
        yield
    finally:
        jit.ENABLED = saved


def tracks(seed: int, B: int, T: int, missing: str) -> np.ndarray:
    """Random-walk boxes (B, T, 4) around 200 px; ``missing``: none, isolated (5 %) or runs (40–60 % of frames)."""
    rng = np.random.default_rng(seed)
    y = 200.0 + np.cumsum(rng.normal(0.0, 2.0, (B, T, 4)), axis=1)
    if missing == "isolated":
        y[rng.random((B, T)) < 0.05] = np.nan
    elif missing == "runs":
        share = rng.uniform(0.4, 0.6)
        for b in range(B):
            gone = np.zeros(T, bool)
            while gone.mean() < share:
                start = rng.integers(0, T)
                gone[start:start + rng.integers(1, 12)] = True
            y[b, gone] = np.nan
    return y


def assert_matches(fast: np.ndarray, ref: np.ndarray, y: np.ndarray) -> None:
    """≤ RTOL relative to the track's scale (positions: max |y|, velocities: that per τ), times (1 + d)² at a frame
    d frames after the latest valid sample — extrapolating a fit across a gap of d frames amplifies its rounding by
    about d², in the reference as in the kernel."""
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(ref))
    B, T, M = y.shape
    valid = np.isfinite(y).all(axis=2)
    frames = np.arange(T)
    latest = np.maximum.accumulate(np.where(valid, frames, -1), axis=1)
    gap = np.where(latest >= 0, frames - latest, 0)
    scale = np.nanmax(np.abs(y), axis=(1, 2), initial=1.0)[:, None, None] * (1.0 + gap[:, :, None]) ** 2
    scale = np.concatenate([scale.repeat(M, axis=2), scale.repeat(fast.shape[2] - M, axis=2) / TAU], axis=2)
    err = np.abs(np.where(np.isnan(ref), 0.0, fast - ref))
    worst = np.unravel_index(np.argmax(err / scale), err.shape)
    assert err[worst] <= RTOL * scale[worst], f"difference {err[worst]:.3g} at {worst} > {RTOL} × {scale[worst]:.3g}"


def both(name: str, y: np.ndarray, positions: bool = False, **params: object) -> tuple[np.ndarray, np.ndarray]:
    flt = filters.make(name, filters.constant_velocity(TAU, ndim=4), **params)
    run = flt.positions if positions else flt.run
    with kernels(True):
        fast = run(y)
    with kernels(False):
        ref = run(y)
    return fast, ref


shapes = st.tuples(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(1, 90),
                   st.sampled_from(["none", "isolated", "runs"]))


@settings(max_examples=40, deadline=None)
@given(shape=shapes, name=st.sampled_from(["ufir", "ufir_cmn"]), data=st.data())
def test_ufir_family_scan_equals_the_reference(shape: tuple[int, int, int, str], name: str, data: st.DataObject) -> None:
    seed, B, T, missing = shape
    y = tracks(seed, B, T, missing)
    horizon = np.array(data.draw(st.lists(st.integers(2, T + 10), min_size=B, max_size=B)))
    params: dict[str, object] = {"horizon": horizon}
    if name == "ufir_cmn":
        params["psi"] = np.array(data.draw(st.lists(st.floats(0.0, 0.95), min_size=B, max_size=B)))
    assert_matches(*both(name, y, **params), y)
    fast, ref = both(name, y, positions=True, **params)
    assert_matches(fast, ref, y[..., :fast.shape[2]])


@pytest.mark.parametrize("missing", ["none", "isolated", "runs"])
def test_ufir_scan_equals_the_literal_algorithm(missing: str) -> None:
    """Algorithm 2 of [Shmaliy-CMN] run literally, one output at a time (ψ = 0.6, N = 12, with start-up)."""
    y = tracks(3, 2, 60, missing)
    axis = filters.constant_velocity(TAU, ndim=1).axis()
    with kernels(True):
        fast = filters.make("ufir_cmn", filters.constant_velocity(TAU, ndim=4), horizon=12, psi=0.6).run(y)
    for b in range(2):
        for m in range(4):
            ref = ufir_iterative(y[b, :, m], axis.F, axis.H, 12, 0.6)
            assert_matches(fast[b][:, [m, 4 + m]][None], ref[None], y[b:b + 1, :, m:m + 1])


@settings(max_examples=30, deadline=None)
@given(shape=shapes, name=st.sampled_from(["oufir", "ofir", "fir"]), data=st.data())
def test_window_kf_scan_equals_the_reference(shape: tuple[int, int, int, str], name: str, data: st.DataObject) -> None:
    """OUFIR, OFIR and Kwon's FIR: start-up and gappy windows by the compiled scan vs the numpy KF / associative scan,
    with per-track horizons and noise ratios (one shared tuning or per track, so that box tracks share compositions)."""
    seed, B, T, missing = shape
    y = tracks(seed, B, T, missing)
    draw = lambda lo, hi: np.array(data.draw(st.lists(st.floats(lo, hi), min_size=B, max_size=B)))  # noqa: E731
    params: dict[str, object] = {"horizon": np.array(data.draw(st.lists(st.integers(2, T + 10), min_size=B, max_size=B))),
                                 "sigma_w": draw(0.1, 300.0), "sigma_v": draw(0.5, 20.0)}
    if data.draw(st.booleans()):
        params = {key: value[0] for key, value in params.items()}  # type: ignore[index]
    assert_matches(*both(name, y, **params), y)
    fast, ref = both(name, y, positions=True, **params)
    assert_matches(fast, ref, y)


@pytest.mark.parametrize("name", ["oufir", "ofir", "fir"])
def test_window_kf_scan_in_threads_equals_one_thread_bit_for_bit(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The scan split over 3 threads (threads.in_threads, forced by a small MIN_WORK) gives the one-thread result
    exactly and the reference to RTOL, on a batch mixing clean tracks (FFT kernel + scanned start-up) and gappy ones
    (every frame scanned), with per-track horizons."""
    y = tracks(11, 9, 150, "isolated")
    y[[2, 5]] = tracks(12, 2, 150, "none")
    params = {"horizon": np.array([4, 30, 30, 61, 8, 30, 30, 2, 200]), "sigma_w": 40.0, "sigma_v": 3.0}
    flt = filters.make(name, filters.constant_velocity(TAU, ndim=4), **params)
    slices: list[int] = []
    monkeypatch.setattr(window_scan_kernels, "in_threads", counting_splits(slices))
    monkeypatch.setattr(threads, "MIN_WORK", 1)
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, "3")
    with kernels(True):
        many = flt.run(y)
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, "1")
    with kernels(True):
        one = flt.run(y)
    with kernels(False):
        ref = flt.run(y)
    assert slices[0] == 3 and slices[-1] == 1  # split over 3 threads, then run in one
    np.testing.assert_array_equal(many, one)
    assert_matches(many, ref, y)


def test_a_failed_scan_estimate_is_reported_not_replaced(monkeypatch: pytest.MonkeyPatch) -> None:
    """A window of >= 2 valid samples whose scan estimate is NaN (counted by the kernel) raises FloatingPointError
    instead of taking the unobservable windows' fallback."""
    scan = window_scan_kernels.window_kf_scan

    def failing(*args: object) -> int:
        scan(*args)
        X = args[-1]
        X[0, -1] = np.nan  # type: ignore[index]
        return 1

    monkeypatch.setattr(window_scan_kernels, "window_kf_scan", failing)
    y = tracks(1, 2, 40, "isolated")
    with kernels(True), pytest.raises(FloatingPointError, match="no finite estimate for channel 0 at frame 39"):
        filters.make("oufir", filters.constant_velocity(TAU, ndim=4), horizon=10).run(y)
