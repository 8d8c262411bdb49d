"""The simulation's compiled kernels (``bboxtune.envs.data.simulate_kernels``) against their numpy references: bit for
bit (the episodes of a seed must not depend on ``$BBOXTUNE_JIT``), on random tracks of every kind — white and coloured
noise, 1, 2 and 4 coordinates, sampling-time errors, log sizes reflected many times at tight size bounds."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune.envs.data import simulate
from bboxtune.envs.data.scenario_ranges import ScenarioRanges
from bboxtune.envs.data.simulate import Scenario
from bboxtune.filters import jit
from tests.kernel_modes import both

seeds = st.integers(0, 2**32 - 1)


@settings(max_examples=40, deadline=None)
@given(seeds, st.integers(1, 4), st.integers(2, 60), st.integers(1, 4),
       st.lists(st.one_of(st.just(0.0), st.floats(0.0, 0.999)), min_size=4, max_size=4))
def test_colour_equals_lfilter(seed: int, B: int, T: int, C: int, psis: list[float]) -> None:
    e = np.random.default_rng(seed).standard_normal((B, T, C)) * 3.0
    kernel, reference = both(lambda: simulate._colour_each(e.copy(), psis[:B]))
    np.testing.assert_array_equal(kernel, reference)


@settings(max_examples=40, deadline=None)
@given(seeds, st.integers(1, 3), st.integers(2, 80), st.sampled_from([1, 2, 4]), st.floats(0.01, 1.0),
       st.floats(0.0, 0.5), st.floats(0.01, 5.0), st.floats(1.0, 1.5))
def test_assemble_equals_numpy(seed: int, B: int, T: int, ndim: int, tau: float, delta: float, sigma_log_size: float,
                               width: float) -> None:
    """Per-track and shared τ, δ, sizes and bounds; a log-size noise up to 5/s² between bounds ``width``× apart folds
    the sizes many times."""
    rng = np.random.default_rng(seed)
    C = ndim
    p0, v0 = rng.normal(0, 10, (B, C)), rng.normal(0, 1, (B, C))
    w = rng.standard_normal((B, T - 1, C)) * np.r_[[30.0] * min(C, 2), [sigma_log_size] * (C - 2)]
    cmn = rng.standard_normal((B, T, C))
    if ndim == 4:
        p0[:, 2:] = 0.0
        sizes0 = rng.uniform(20.0, 40.0, (B, 1, 2))
        bounds = np.concatenate([sizes0.min(axis=2, keepdims=True) / width, sizes0.max(axis=2, keepdims=True) * width], axis=2)
    else:
        sizes0 = bounds = np.empty(0)
    per_track = (p0, v0, w, rng.uniform(tau, 2 * tau, (B, 1, 1)), np.full((B, 1, 1), delta), cmn, sizes0, bounds)
    shared = (p0, v0, w, tau, delta, cmn, sizes0[0, 0] if ndim == 4 else sizes0, bounds[0, 0] if ndim == 4 else bounds)
    for args in (per_track, shared):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(jit, "ENABLED", True)
            kernel = simulate.assemble(*args)
        for got, want in zip(kernel, simulate.assemble_numpy(*args), strict=True):
            np.testing.assert_array_equal(got, want)


@settings(max_examples=10, deadline=None)
@given(seeds, st.sampled_from([1, 2, 4]), st.sampled_from(["cv", "otb"]))
def test_simulate_each_same_with_and_without_kernels(seed: int, ndim: int, motion: str) -> None:
    ndim = 4 if motion == "otb" else ndim
    ranges = ScenarioRanges(ndim=ndim, motion=motion, n_frames=(60, 60), delta=(0.0, 0.01))

    def draw() -> list[simulate.Track]:
        rngs = [np.random.default_rng(seed + i) for i in range(3)]
        return simulate.simulate_each([ranges.sample(g) for g in rngs], rngs)
    kernel, reference = both(draw)
    for a, b in zip(kernel, reference, strict=True):
        for field in ("truth", "truth_state", "y"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    scenario = Scenario(sigma_w_log_size=2.0, psi=0.5, size_bounds=(40.0, 70.0))
    tracks = both(lambda: simulate.simulate(scenario, np.random.default_rng(seed), 2))
    for field in ("truth", "truth_state", "y"):
        np.testing.assert_array_equal(getattr(tracks[0], field), getattr(tracks[1], field))


@pytest.mark.parametrize("kwargs", [{}, {"scenario": "nonstationary", "detection_dropout": "runs"}])
def test_env_reset_same_with_and_without_kernels(kwargs: dict[str, str]) -> None:
    """``reset(seed)``: the same episode (bit for bit) and observation (to float32 rounding) in both modes."""
    def episodes() -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        env = gym.make("bboxtune/FilterTune-v0", backend="kf", track_length=120, **kwargs)
        out = []
        for seed in (0, 7, 12345):
            obs, _ = env.reset(seed=seed)
            out.append((obs, env.unwrapped.episode.y, env.unwrapped.episode.truth))
        return out
    for (obs_k, y_k, truth_k), (obs_n, y_n, truth_n) in zip(*both(episodes), strict=True):
        np.testing.assert_array_equal(y_k, y_n)
        np.testing.assert_array_equal(truth_k, truth_n)
        np.testing.assert_allclose(obs_k, obs_n, rtol=1e-6, atol=1e-6)
