"""Batches split over threads (bboxtune.filters.threads.in_threads): the simulation, the filters of every back end,
the observation features, the scoring and the batched env give bit for bit what one thread gives."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from bboxtune.envs.data.scenario_ranges import ScenarioRanges
from bboxtune.envs.data.simulate import simulate_each
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.features import measurement_features
from bboxtune.envs.episodes.scoring import run_tracks, score_tracks
from bboxtune.envs.tune_env import FilterTuneEnv
from bboxtune.envs.vector import TuneBatch
from bboxtune.filters import threads
from bboxtune.filters.registry import filter_class
from tests.kernel_modes import counting_splits


@pytest.fixture
def split_calls(monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[[Callable[[], Any]], tuple[Any, Any, list[int]]]]:
    """``run(fn)``: fn's result on one thread, then with every in_threads call split over 3 threads (MIN_WORK 1), and
    the slice counts of the split calls (to show they were split)."""
    counts: list[int] = []
    counted = counting_splits(counts)

    def run(fn: Callable[[], Any]) -> tuple[Any, Any, list[int]]:
        monkeypatch.setenv(threads.KERNEL_ENV_VAR, "1")
        one = fn()
        monkeypatch.setenv(threads.KERNEL_ENV_VAR, "3")
        monkeypatch.setattr(threads, "MIN_WORK", 1)
        counts.clear()
        for module in ("bboxtune.envs.data.simulate", "bboxtune.envs.episodes.features", "bboxtune.envs.episodes.scoring",
                       "bboxtune.filters.batch"):
            monkeypatch.setattr(f"{module}.in_threads", counted)
        many = fn()
        monkeypatch.undo()
        return one, many, list(counts)

    yield run


def _boxes(n: int, T: int, seed: int, missing: float) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        y = np.abs(60 + np.cumsum(rng.normal(0, 2, (T, 4)), axis=0)) + 5
        y[rng.random(T) < missing] = np.nan
        out.append(y)
    return out


@pytest.mark.parametrize("motion", ["cv", "otb"])
def test_the_simulation(split_calls, motion: str) -> None:
    ranges = ScenarioRanges(motion=motion, n_frames=(80, 80), delta=(0.0, 0.01))

    def draw() -> list[tuple[np.ndarray, ...]]:
        rngs = [np.random.default_rng(100 + i) for i in range(7)]
        return [tuple(t) for t in simulate_each([ranges.sample(g) for g in rngs], rngs)]
    one, many, counts = split_calls(draw)
    assert counts == [3]
    for a, b in zip(one, many, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("kwargs, split", [({}, 3), ({"detection_dropout": "runs", "sim_noise": "box",
                                                       "outlier_rate_range": (0.0, 0.1)}, 3),
                                             ({"scenario": "nonstationary"}, 0), ({"motion": "otb"}, 3)])
def test_the_simulated_source(split_calls, kwargs: dict[str, Any], split: int) -> None:
    """``draw_many``: the episodes' boxes, nominal parameters and scenarios (non-stationary episodes are simulated one
    at a time: no split)."""
    source = FilterTuneEnv(track_length=80, **kwargs).source
    one, many, counts = split_calls(lambda: source.draw_many(list(range(50, 57))))
    assert max(counts, default=0) == split
    for a, b in zip(one, many, strict=True):
        np.testing.assert_array_equal(a.y, b.y)
        np.testing.assert_array_equal(a.truth, b.truth)
        assert (a.nominal, a.meta, a.scenario, a.tau) == (b.nominal, b.meta, b.scenario, b.tau)


@pytest.mark.parametrize("backend", BACKENDS)
def test_every_back_end_on_a_batch_of_tracks(split_calls, backend: str) -> None:
    """Tracks with missing frames, each with its own parameters, at two τ (the UKF runs each τ apart), through
    ``run_tracks`` (the window-scan FIRs keep their tracks together and split their scan, here over 3 threads too)."""
    ys, n = _boxes(7, 60, 1, 0.2), 7
    taus = [1 / 30] * 4 + [1 / 7] * 3
    params = {"sigma_w": np.geomspace(5, 500, n), "sigma_v": np.geomspace(0.5, 8, n), "psi": np.linspace(0, 0.9, n),
              "horizon": np.arange(4, 4 + 5 * n, 5), "std_weight_position": np.geomspace(0.01, 0.2, n),
              "std_weight_velocity": np.geomspace(0.001, 0.02, n), "std_aspect_measurement": np.geomspace(1e-3, 1e-1, n)}
    one, many, counts = split_calls(lambda: run_tracks(backend, ys, taus, params))
    assert max(counts, default=0) == (3 if filter_class(backend).SPLIT_TRACKS else 0)  # else: the scan splits itself
    for a, b in zip(one, many, strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_features_and_the_scores(split_calls) -> None:
    y, truth = np.stack(_boxes(8, 90, 2, 0.1)), np.stack(_boxes(8, 90, 3, 0.0))
    rule = np.where(np.isfinite(y), y + 0.5, np.nan)

    def both() -> tuple[np.ndarray, dict[str, np.ndarray]]:
        obs = measurement_features(y, np.full(8, 0.04), 2.0, np.geomspace(5, 50, 8), rule, msd=True)
        return obs, score_tracks(list(rule), list(truth))
    (obs_one, scores_one), (obs_many, scores_many), counts = split_calls(both)
    assert counts == [3, 3]
    np.testing.assert_array_equal(obs_one, obs_many)
    for key, value in scores_one.items():
        np.testing.assert_array_equal(value, scores_many[key])


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn", "oufir"])
def test_the_batched_env(split_calls, backend: str) -> None:
    """Two steps of 6 envs: observations, rewards and step infos."""
    def steps() -> list[Any]:
        batch = TuneBatch(6, backend=backend, track_length=100)
        batch.seed(4)
        out: list[Any] = [batch.reset()[0]]
        for i in range(2):
            actions = np.random.default_rng(i).uniform(-1, 1, (6, batch.env.action_map.dim)).astype(np.float32)
            rewards, infos = batch.step(actions)
            out += [rewards, [{k: v for k, v in info.items() if k != "params"} for info in infos], batch.reset()[0]]
        return out
    one, many, counts = split_calls(steps)
    assert counts and max(counts) == 3
    for a, b in zip(one, many, strict=True):
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b
