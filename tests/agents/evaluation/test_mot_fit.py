"""bboxtune.agents.evaluation.mot_fit: the simulator's detection noise fitted to MOT statistics, and measured back on the
simulator."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune.agents.evaluation.mot_fit import (
    MIN_LAG_PAIRS,
    TAU_RANGE,
    NoiseStats,
    box_aspect,
    fit_sim_kwargs,
    measure_sim,
    noise_stats,
    sim_identities,
    stationary_std,
)
from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.data.mot import DetectionStats, MOTIdentity, detection_stats
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.sources import make_source

ASPECT = 0.5


def hand_made(lag1: np.ndarray, miss_rate: np.ndarray, mean_run: np.ndarray, levels: np.ndarray,
              pooled_std: np.ndarray, *, pairs: int = 50, n_frames: int = 100) -> NoiseStats:
    """Statistics of len(miss_rate) identities; ``levels``: each identity's error std in model units (all four
    coordinates alike), ``pooled_std``: the pooled error std / h (4,)."""
    n = len(miss_rate)
    units = np.array([ASPECT, 1.0, ASPECT, 1.0])
    pooled = DetectionStats(
        n_identities=n, n_matched=50 * n, error_mean_rel=np.zeros(4), error_std_rel=np.asarray(pooled_std, float),
        abs_error_height_corr=np.full(4, 0.5), lag1_corr=np.full(4, 0.5), n_lag_pairs=pairs * n,
        miss_rate=np.asarray(miss_rate, float), miss_runs=np.ones(5), track_length=np.full(n, n_frames))
    return NoiseStats(pooled=pooled, lag1_corr=np.asarray(lag1, float), lag_pairs=np.full(n, pairs),
                      error_mean_rel=np.zeros((n, 4)), error_std_rel=np.asarray(levels, float)[:, None] * units,
                      matched=np.full(n, 50), mean_miss_run=np.asarray(mean_run, float),
                      median_height=np.linspace(80.0, 300.0, n), error_rel_cx=np.zeros(0))


def test_the_fitted_ranges_span_the_inputs_and_match_the_error_power() -> None:
    rng = np.random.default_rng(0)
    n = 40
    lag1 = rng.uniform(0.3, 0.7, (n, 4))
    miss_rate = rng.uniform(0.2, 0.5, n)
    mean_run = np.exp(rng.uniform(np.log(2), np.log(6), n))
    levels = rng.uniform(0.05, 0.1, n)
    stats = hand_made(lag1, miss_rate, mean_run, levels, pooled_std=[0.03, 0.06, 0.03, 0.06])
    kwargs = fit_sim_kwargs(stats, ASPECT)
    EnvConfig(**kwargs)
    for name, values, (low, high) in (("psi_range", lag1, (0.3, 0.7)), ("miss_rate_range", miss_rate, (0.2, 0.5)),
                                      ("miss_run_range", mean_run, (2.0, 6.0))):
        lo, hi = kwargs[name]
        assert low <= lo < np.median(values) < hi <= high, (name, kwargs[name])
        assert lo == pytest.approx(np.quantile(values, 0.1), rel=1e-3) and hi == pytest.approx(np.quantile(values, 0.9), rel=1e-3)
    # the pooled stationary std of the drawn CMN is the rms of the model-unit error stds (0.03 / 0.5 = 0.06, 0.06)
    assert stationary_std(kwargs["psi_range"], kwargs["cmn_rel_range"]) == pytest.approx(0.06, rel=1e-3)
    lo, hi = kwargs["cmn_rel_range"]
    assert hi / lo == pytest.approx(np.quantile(levels, 0.9) / np.quantile(levels, 0.1), rel=1e-3)
    assert kwargs["box_size_range"][0] >= 80 and kwargs["box_size_range"][1] <= 300
    assert (kwargs["source"], kwargs["sim_noise"], kwargs["detection_dropout"], kwargs["track_length"]) == (
        "sim", "box", "runs", 100)
    assert kwargs["tau_range"] == pytest.approx(TAU_RANGE, rel=1e-3)
    assert "outlier_rate_range" not in kwargs  # wrong boxes stay off (no IoU >= 0.5 match is one)


def test_stationary_std_is_the_closed_form() -> None:
    assert stationary_std((0.6, 0.6), (0.08, 0.08)) == pytest.approx(0.08 / np.sqrt(1 - 0.36))
    rng = np.random.default_rng(1)
    psi, sigma = rng.uniform(0.2, 0.8, 400_000), np.exp(rng.uniform(np.log(0.05), np.log(0.2), 400_000))
    assert stationary_std((0.2, 0.8), (0.05, 0.2)) == pytest.approx(np.sqrt(np.mean(sigma**2 / (1 - psi**2))), rel=5e-3)


def test_ranges_are_clipped_and_poorly_measured_identities_ignored() -> None:
    n = 10
    lag1 = np.full((n, 4), 0.99)
    lag1[:3] = -0.9  # identities with too few pairs of consecutive detections: left out
    stats = hand_made(lag1, np.full(n, 0.99), np.full(n, 3.0), np.full(n, 0.05), pooled_std=[0.02, 0.05, 0.02, 0.05])
    stats = NoiseStats(**{**stats.__dict__, "lag_pairs": np.r_[np.full(3, MIN_LAG_PAIRS - 1), np.full(n - 3, 50)]})
    kwargs = fit_sim_kwargs(stats, ASPECT)
    assert kwargs["psi_range"] == [0.95, 0.95] and kwargs["miss_rate_range"] == [0.95, 0.95]
    assert kwargs["cmn_rel_range"][0] == kwargs["cmn_rel_range"][1]  # one error level: a point range


@pytest.mark.parametrize(("change", "message"), [
    ({"lag_pairs": np.full(5, MIN_LAG_PAIRS - 1)}, "no identity with 20 pairs"),
    ({"mean_miss_run": np.full(5, np.nan)}, "no missed run"),
])
def test_what_cannot_be_fitted_is_a_value_error(change: dict, message: str) -> None:
    stats = hand_made(np.full((5, 4), 0.5), np.full(5, 0.3), np.full(5, 3.0), np.full(5, 0.05), [0.02, 0.05, 0.02, 0.05])
    with pytest.raises(ValueError, match=message):
        fit_sim_kwargs(NoiseStats(**{**stats.__dict__, **change}), ASPECT)
    with pytest.raises(ValueError, match="aspect"):
        fit_sim_kwargs(stats, 0.0)


def test_the_simulated_statistics_come_back_near_the_fitted_ones() -> None:
    n = 20
    stats = hand_made(np.full((n, 4), 0.6), np.full(n, 0.3), np.full(n, 3.0), np.full(n, 0.08),
                      pooled_std=[ASPECT * 0.08, 0.08, ASPECT * 0.08, 0.08], n_frames=120)
    kwargs = fit_sim_kwargs(stats, ASPECT)
    assert (kwargs["psi_range"], kwargs["miss_rate_range"], kwargs["miss_run_range"]) == ([0.6, 0.6], [0.3, 0.3], [3.0, 3.0])
    sim = measure_sim(kwargs, 300, 7, aspect=ASPECT).pooled
    assert sim.n_identities == 300 and set(sim.track_length) == {120}
    np.testing.assert_allclose(sim.lag1_corr, 0.6, atol=0.05)
    np.testing.assert_allclose(sim.error_std_rel, [0.04, 0.08, 0.04, 0.08], rtol=0.1)  # the stationary std, per unit
    assert sim.miss_rate.mean() == pytest.approx(0.3, abs=0.03)
    assert sim.miss_runs.mean() == pytest.approx(3.0, rel=0.15)


def test_sim_episodes_are_measured_on_pedestrian_shaped_boxes() -> None:
    kwargs = {"source": "sim", "sim_noise": "box", "track_length": 40, "detection_dropout": "runs",
              "miss_rate_range": (0.4, 0.5)}
    (shaped,) = sim_identities(kwargs, 1, 3, aspect=0.4)
    (episode,) = make_source(EnvConfig(**kwargs)).draw_many([3])
    truth, y = xywh_to_cxcywh(shaped.truth), xywh_to_cxcywh(shaped.measured)
    assert shaped.identity == 3 and shaped.tau == episode.tau
    np.testing.assert_allclose(truth[:, 2] / truth[:, 3], 0.4)
    np.testing.assert_allclose(truth[:, [0, 1, 3]], episode.truth[:, [0, 1, 3]])
    np.testing.assert_array_equal(np.isnan(y), np.isnan(episode.y))
    measured = ~np.isnan(y[:, 0])
    assert 2 <= measured.sum() < 40 and np.array_equal(np.isfinite(shaped.scores), measured)
    np.testing.assert_allclose(y[:, [1, 3]], episode.y[:, [1, 3]])  # cy, h: unchanged
    # the drawn u of cx and w: relative to the reshaped w exactly as to the drawn one
    np.testing.assert_allclose(((y - truth)[:, 0] / truth[:, 2])[measured],
                               ((episode.y - episode.truth)[:, 0] / episode.truth[:, 2])[measured])
    np.testing.assert_allclose((y[:, 2] / truth[:, 2])[measured], (episode.y[:, 2] / episode.truth[:, 2])[measured])


def test_measure_sim_refuses_what_it_cannot_measure() -> None:
    with pytest.raises(ValueError, match="'sim' source only"):
        measure_sim({"source": "otb"}, 5, 0, aspect=0.4)
    with pytest.raises(ValueError, match="n_episodes=0"):
        measure_sim({"source": "sim"}, 0, 0, aspect=0.4)


def identity(ident: int, cx_offset: float, n: int, rng: np.random.Generator, missed: tuple[int, ...] = ()) -> MOTIdentity:
    truth = np.tile([100.0, 200.0, 40.0, 100.0], (n, 1))
    y = truth + np.c_[np.full(n, cx_offset * 100), rng.normal(0, 3.0, (n, 3))]
    y[list(missed)] = np.nan
    return MOTIdentity(sequence="s", identity=ident, first_frame=1, truth=cxcywh_to_xywh(truth),
                       measured=cxcywh_to_xywh(y), scores=np.where(np.isnan(y[:, 0]), np.nan, 1.0), tau=0.1)


def test_noise_stats_are_detection_stats_pooled_and_per_identity() -> None:
    rng = np.random.default_rng(2)
    long, other, short = identity(1, 0.1, 60, rng, missed=(10, 11, 12)), identity(2, -0.1, 60, rng), identity(3, 0.1, 12, rng)
    stats = noise_stats([long, other, short])
    assert stats.pooled.n_identities == 3 and stats.pooled.n_matched == 57 + 60 + 12
    assert list(stats.lag_pairs) == [55, 59, 11] and list(stats.well_measured) == [True, True, False]
    np.testing.assert_allclose(stats.lag1_corr[0], detection_stats([long]).lag1_corr)
    assert np.isnan(stats.lag1_corr[2]).all()
    np.testing.assert_allclose(stats.error_std_rel[1], detection_stats([other]).error_std_rel)
    np.testing.assert_allclose(stats.mean_miss_run, [3.0, np.nan, np.nan])
    np.testing.assert_allclose(stats.median_height, 100.0)
    np.testing.assert_allclose(np.sort(stats.error_rel_cx), np.sort(np.r_[np.full(69, 0.1), np.full(60, -0.1)]))
    share = stats.between_share()
    assert share[0] == pytest.approx(1.0) and (share[1:] < 0.1).all()  # cx: constant per identity; the rest white
    assert box_aspect([long, short]) == pytest.approx(0.4)
