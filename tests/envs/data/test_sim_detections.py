"""Detection errors (envs/data/sim_detections.py): the miss chain's rate and run lengths, the kept ends, the
wrong boxes, and reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune.envs.data.sim_detections import (
    OUTLIER_LOG_SIZE_STD,
    OUTLIER_SHIFT,
    DetectionModel,
    gilbert_elliott,
    keep_ends,
    reachable_run,
)


def _model(dropout: str = "runs", rate: tuple[float, float] = (0.0, 0.6), run: tuple[float, float] = (1.0, 20.0),
           outliers: tuple[float, float] = (0.0, 0.0)) -> DetectionModel:
    return DetectionModel(dropout, rate, run, outliers)


def _rngs(seeds: range | list[int]) -> list[np.random.Generator]:
    return [np.random.default_rng((s, 5)) for s in seeds]


def _tracks(n: int, n_frames: int, seed: int = 0) -> np.ndarray:
    """n tracks (n, T, 4) of positive boxes (cx, cy, w, h) in px."""
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.uniform(100, 500, (n, n_frames, 2)), rng.uniform(20, 200, (n, n_frames, 2))], axis=-1)


def _runs(states: np.ndarray) -> np.ndarray:
    """The lengths of the runs of True in the rows of ``states`` (B, T), but those cut by a row's start or end."""
    lengths: list[int] = []
    for row in states:
        edges = np.diff(np.concatenate([[0], row.astype(int), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        whole = (starts > 0) & (ends < len(row))
        lengths.extend((ends - starts)[whole].tolist())
    return np.array(lengths)


@pytest.mark.parametrize("rate, run", [(0.44, 3.0), (0.25, 2.0), (0.6, 20.0), (0.1, 1.0), (0.9, 50.0)])
def test_the_chain_has_the_requested_miss_rate_and_mean_run_length(rate: float, run: float) -> None:
    B, T = 200, 5000
    u = np.random.default_rng(1).random((B, T))
    states = gilbert_elliott(u, np.full(B, rate), np.full(B, run))
    assert states.mean() == pytest.approx(rate, abs=0.005)
    assert _runs(states).mean() == pytest.approx(run, rel=0.03)
    assert states[:, 0].mean() == pytest.approx(rate, abs=0.1)  # the stationary start


def test_the_chain_equals_the_step_by_step_recurrence() -> None:
    rng = np.random.default_rng(2)
    B, T = 300, 400
    rate = rng.uniform(0, 0.95, B)
    run = reachable_run(rate, np.exp(rng.uniform(0, np.log(1000), B)))
    u = rng.random((B, T))
    start, stay = rate / ((1 - rate) * run), 1 - 1 / run
    state = u[:, 0] < rate
    expected = [state]
    for t in range(1, T):
        state = np.where(state, u[:, t] < stay, u[:, t] < start)
        expected.append(state)
    np.testing.assert_array_equal(gilbert_elliott(u, rate, run), np.stack(expected, axis=1))


def test_an_unreachable_run_length_is_raised_to_the_shortest_that_reaches_the_rate() -> None:
    run = reachable_run(np.array([0.0, 0.5, 0.6, 0.9]), np.array([1.0, 1.0, 2.0, 3.0]))
    np.testing.assert_allclose(run, [1.0, 1.0, 2.0, 9.0])
    u = np.random.default_rng(3).random((100, 4000))
    states = gilbert_elliott(u, np.full(100, 0.9), np.full(100, 9.0))
    assert states.mean() == pytest.approx(0.9, abs=0.01)
    assert not (~states[:, 1:-1] & ~states[:, :-2] & ~states[:, 2:]).any()  # every detected run lasts one frame


def test_bernoulli_misses_at_the_drawn_rate_and_keeps_the_first_and_last_frame() -> None:
    model = _model("bernoulli", rate=(0.3, 0.3))
    y = _tracks(64, 1000)
    _, missing, outlier = model.apply(y, y, model.draw(_rngs(range(64)), 1000))
    assert missing[:, 1:-1].mean() == pytest.approx(0.3, abs=0.01)
    assert not missing[:, [0, -1]].any() and not outlier.any()
    runs = _runs(missing)
    assert runs.mean() == pytest.approx(1 / 0.7, rel=0.05)  # independent frames: geometric runs


@pytest.mark.parametrize("dropout", ["bernoulli", "runs"])
def test_missing_frames_are_nan_rows_and_the_first_and_last_measured_frame_stay(dropout: str) -> None:
    model = _model(dropout, rate=(0.95, 0.95), run=(1000.0, 1000.0))
    y = _tracks(50, 40)
    y[:10, :3] = np.nan  # tracks that start and end without a measurement
    y[10:20, -5:] = np.nan
    out, missing, _ = model.apply(y, y, model.draw(_rngs(range(50)), 40))
    measured = np.isfinite(y).all(axis=-1)
    assert not (missing & ~measured).any()
    np.testing.assert_array_equal(np.isnan(out).all(axis=-1), missing | ~measured)
    np.testing.assert_array_equal(out[~missing], y[~missing])
    kept = np.isfinite(out).all(axis=-1)
    assert kept[:10, 3].all() and kept[10:20, -6].all() and kept[20:, [0, -1]].all()
    assert (kept.sum(axis=1) >= 2).all()


def test_keep_ends_leaves_a_track_without_measurements_alone() -> None:
    measured = np.array([[False, False, False], [False, True, False]])
    np.testing.assert_array_equal(keep_ends(np.zeros_like(measured), measured), np.zeros_like(measured))


def test_outliers_hit_measured_frames_with_truth_only_and_are_nearby_boxes_of_the_documented_kind() -> None:
    model = _model("runs", rate=(0.4, 0.4), run=(3.0, 3.0), outliers=(0.3, 0.3))
    truth = _tracks(64, 500)
    y = truth + np.random.default_rng(4).normal(0, 2, truth.shape)
    truth[:, 100:110] = np.nan  # frames without ground truth: never given a wrong box
    drawn = model.draw(_rngs(range(64)), 500)
    out, missing, outlier = model.apply(y, truth, drawn)
    assert not (outlier & missing).any() and not outlier[:, 100:110].any()
    assert outlier.sum() / (~missing).sum() == pytest.approx(0.3 * 490 / 500, abs=0.02)
    np.testing.assert_array_equal(out[~outlier & ~missing], y[~outlier & ~missing])
    wrong, true = out[outlier], truth[outlier]
    log_size = np.log(wrong[:, 2:] / true[:, 2:])
    np.testing.assert_allclose(log_size[:, 0], log_size[:, 1])  # the same aspect ratio
    assert log_size[:, 0].std() == pytest.approx(OUTLIER_LOG_SIZE_STD, rel=0.05)
    shift = np.hypot(*(wrong[:, :2] - true[:, :2]).T) / true[:, 3]
    assert OUTLIER_SHIFT[0] <= shift.min() and shift.max() <= OUTLIER_SHIFT[1]
    angle = np.arctan2(*(wrong[:, [1, 0]] - true[:, [1, 0]]).T)
    assert np.histogram(angle, 4, (-np.pi, np.pi))[0].min() > 0.2 * len(angle)  # every direction


def test_parameters_are_drawn_from_their_ranges_and_reported_for_the_errors_in_use() -> None:
    model = _model("runs", rate=(0.1, 0.5), run=(2.0, 50.0), outliers=(0.0, 0.2))
    drawn = model.draw(_rngs(range(2000)), 8)
    assert 0.1 <= drawn.miss_rate.min() and drawn.miss_rate.max() <= 0.5
    assert drawn.miss_rate.mean() == pytest.approx(0.3, abs=0.01)
    assert np.log(drawn.miss_run).mean() == pytest.approx(np.log(10.0), abs=0.05)  # log-uniform on [2, 50]
    assert drawn.outlier_rate.max() <= 0.2
    assert sorted(model.parameters(drawn)[0]) == ["miss_rate", "miss_run", "outlier_rate"]
    assert sorted(_model("bernoulli").parameters(drawn)[0]) == ["miss_rate"]
    assert sorted(_model("none", outliers=(0.1, 0.1)).parameters(drawn)[0]) == ["outlier_rate"]
    assert not _model("none").active and _model("none", outliers=(0.0, 0.1)).active and _model("bernoulli").active


def test_errors_are_a_function_of_the_seed_and_a_batch_equals_each_episode_alone() -> None:
    model = _model("runs", outliers=(0.0, 0.3))
    y = _tracks(16, 300)
    out, missing, outlier = model.apply(y, y, model.draw(_rngs(range(16)), 300))
    again, *_ = model.apply(y, y, model.draw(_rngs(range(16)), 300))
    np.testing.assert_array_equal(out, again)
    for b in range(16):
        alone, m, o = model.apply(y[b:b + 1], y[b:b + 1], model.draw(_rngs([b]), 300))
        np.testing.assert_array_equal(alone[0], out[b])
        np.testing.assert_array_equal(m[0], missing[b])
        np.testing.assert_array_equal(o[0], outlier[b])
    other, *_ = model.apply(y, y, model.draw(_rngs(range(16, 32)), 300))
    assert not np.array_equal(np.isnan(other), np.isnan(out))


def test_the_draws_do_not_depend_on_the_errors_switched_on() -> None:
    y = _tracks(8, 200)
    runs = _model("runs").draw(_rngs(range(8)), 200)
    both = _model("runs", outliers=(0.0, 0.3)).draw(_rngs(range(8)), 200)
    np.testing.assert_array_equal(runs.miss_rate, both.miss_rate)
    np.testing.assert_array_equal(runs.uniform, both.uniform)
    _, missing, _ = _model("runs").apply(y, y, runs)
    _, missing_too, _ = _model("runs", outliers=(0.0, 0.3)).apply(y, y, both)
    np.testing.assert_array_equal(missing, missing_too)  # outliers come on top of the same misses
