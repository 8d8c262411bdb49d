"""Detection errors in the training episodes (``detection_dropout``, ``miss_rate_range``, ``miss_run_range``,
``outlier_rate_range``; envs/data/sim_detections.py): defaults change nothing, dropout blanks measured rows at the
drawn rate and nothing else, every back end runs through the gaps, the batched env draws the same episodes,
and bad settings are refused by name."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs, filters
from bboxtune.envs.data.simulate import simulate_each
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.sources import make_source
from tests.envs.conftest import OTB_ROOT, needs_otb
from tests.envs.test_vector import _single_steps, _tracks

TUNE, RETUNE = "bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"
RUNS = {"detection_dropout": "runs", "outlier_rate_range": (0.0, 0.2)}
HARSH = {"detection_dropout": "runs", "miss_rate_range": (0.5, 0.95), "miss_run_range": (1.0, 1000.0),
         "outlier_rate_range": (0.3, 0.5)}
SIM_CONFIGS = [{}, {"sim_noise": "box"}, {"scenario": "nonstationary"}, {"motion": "otb"},
               {"source": "mix", "mix_weights": (1.0, 0.0, 0.0)}]
SEEDS = list(range(12))


def _missing(y: np.ndarray) -> np.ndarray:
    return np.isnan(y).all(axis=-1)


def test_defaults_draw_the_simulated_measurements_unchanged() -> None:
    cfg = EnvConfig(track_length=200)
    assert (cfg.detection_dropout, cfg.miss_rate_range, cfg.miss_run_range, cfg.outlier_rate_range) == (
        "none", (0.0, 0.6), (1.0, 20.0), (0.0, 0.0))
    episodes = make_source(cfg).draw_many(SEEDS)
    ranges = make_source(cfg).ranges
    rngs = [np.random.default_rng(seed) for seed in SEEDS]
    tracks = simulate_each([ranges.sample(rng) for rng in rngs], rngs)
    for ep, track in zip(episodes, tracks, strict=False):
        np.testing.assert_array_equal(ep.y, track.y)
        assert sorted(ep.scenario) == ["psi", "sigma_w", "sigma_xi"]


@pytest.mark.parametrize("kwargs", SIM_CONFIGS)
@pytest.mark.parametrize("errors", [RUNS, {"detection_dropout": "bernoulli"}, {"outlier_rate_range": (0.1, 0.1)}])
def test_errors_change_only_measured_rows_and_add_their_parameters_to_the_scenario(kwargs: dict, errors: dict) -> None:
    plain = make_source(EnvConfig(track_length=200, **kwargs)).draw_many(SEEDS)
    errs = make_source(EnvConfig(track_length=200, **kwargs, **errors)).draw_many(SEEDS)
    dropout = errors.get("detection_dropout", "none")
    used = {"miss_rate": dropout != "none", "miss_run": dropout == "runs", "outlier_rate": "outlier_rate_range" in errors}
    keys = {k for k, u in used.items() if u}
    n_missed = n_wrong = 0
    for a, b in zip(plain, errs, strict=False):
        np.testing.assert_array_equal(b.truth, a.truth)
        assert b.meta == a.meta and b.tau == a.tau
        assert keys <= b.scenario.keys() and b.scenario == {**a.scenario, **{k: b.scenario[k] for k in keys}}
        missed = _missing(b.y) & ~_missing(a.y)  # frames the source measured, made missing
        assert not (_missing(a.y) & ~_missing(b.y)).any() and not missed[[0, -1]].any()
        n_missed += int(missed.sum())
        n_wrong += int((~_missing(b.y) & (b.y != a.y).any(axis=-1)).sum())  # wrong boxes
        if kwargs.get("sim_noise") != "box":
            assert b.nominal == a.nominal  # the absolute-noise rule's nominal σ: config only
    assert (n_missed > 0) == (dropout != "none") and (n_wrong > 0) == used["outlier_rate"]


def test_dropout_misses_frames_at_the_drawn_rate() -> None:
    kwargs = {"detection_dropout": "runs", "miss_rate_range": (0.3, 0.3), "miss_run_range": (4.0, 4.0)}
    episodes = make_source(EnvConfig(track_length=2000, **kwargs)).draw_many(list(range(64)))
    missing = np.stack([_missing(ep.y) for ep in episodes])
    assert missing[:, 1:-1].mean() == pytest.approx(0.3, abs=0.02)
    assert {(ep.scenario["miss_rate"], ep.scenario["miss_run"]) for ep in episodes} == {(0.3, 4.0)}
    env = gym.make(TUNE, track_length=500, detection_dropout="bernoulli", miss_rate_range=(0.5, 0.5))
    fractions = []
    for seed in range(20):
        env.reset(seed=seed)
        fractions.append(_missing(env.unwrapped.episode.y)[1:-1].mean())
    assert np.mean(fractions) == pytest.approx(0.5, abs=0.03)


def test_an_episode_is_still_a_function_of_its_noise_seed() -> None:
    env = gym.make(TUNE, track_length=120, **RUNS)
    obs, info = env.reset(seed=5)
    y = env.unwrapped.episode.y.copy()
    for _ in range(3):
        env.reset()
    pinned, _ = env.reset(options={"noise_seed": info["track"]["noise_seed"]})
    np.testing.assert_array_equal(env.unwrapped.episode.y, y)
    np.testing.assert_array_equal(pinned, obs)


@pytest.mark.parametrize("backend", filters.NAMES)
def test_every_back_end_filters_through_missing_frames_and_wrong_boxes(backend: str) -> None:
    env = gym.make(TUNE, backend=backend, track_length=64, **HARSH)
    rng = np.random.default_rng(0)
    n_missing = 0
    for seed in range(6):
        obs, _ = env.reset(seed=seed)
        assert np.isfinite(obs).all()
        n_missing += int(_missing(env.unwrapped.episode.y).sum())
        scores = env.unwrapped.score(rng.uniform(-1, 1, (5, env.action_space.shape[0])))
        assert np.isfinite(scores["reward"]).all() and np.isfinite(scores["rmse"]).all()
        _, reward, terminated, _, info = env.step(env.action_space.sample())
        assert terminated and math.isfinite(reward) and math.isfinite(info["rmse"]) and math.isfinite(info["rule_rmse"])
        assert {"miss_rate", "miss_run", "outlier_rate"} <= info["scenario"].keys()
        assert "miss_rate" not in info["track"]  # the drawn rates are the truth: hidden until the step
    assert n_missing > 0  # (a track of 64 frames may miss none: a long mean run may not start within it)


@pytest.mark.parametrize("backend", filters.NAMES)
def test_the_retune_env_runs_through_missing_frames(backend: str) -> None:
    env = gym.make(RETUNE, backend=backend, track_length=64, window=16, history=16, **HARSH)
    for seed in range(2):
        obs, _ = env.reset(seed=seed)
        terminated = False
        while not terminated:
            assert np.isfinite(obs).all()
            obs, reward, terminated, _, info = env.step(env.action_space.sample())
            assert math.isfinite(reward)
        assert "miss_rate" in info["scenario"]


@pytest.mark.parametrize("backend, extra", [("ufir_cmn", RUNS), ("kf_cmn", HARSH),
                                            ("oufir", {"detection_dropout": "bernoulli", "sim_noise": "box"})])
def test_the_batched_env_draws_the_single_envs_episodes_with_dropout(backend: str, extra: dict) -> None:
    kwargs = {"backend": backend, "track_length": 120, **extra}
    venv = envs.make_vec(TUNE, 5, **kwargs)
    obs, infos = venv.reset(seed=3)
    batch = [prepared[0] for prepared in venv.batch.prepared]
    actions = np.random.default_rng(0).uniform(-1, 1, (5, venv.single_action_space.shape[0])).astype(np.float32)
    _, rewards, *_ = venv.step(actions)
    single_obs, single_rewards, _ = _single_steps(kwargs, _tracks(infos, 5), actions)
    np.testing.assert_allclose(obs, single_obs, rtol=1e-6)
    np.testing.assert_allclose(rewards, single_rewards, rtol=1e-9, atol=1e-12)
    env = gym.make(TUNE, **kwargs)
    for ep in batch:
        env.reset(options={"noise_seed": ep.meta["noise_seed"]})
        np.testing.assert_array_equal(env.unwrapped.episode.y, ep.y)  # NaN rows included
        assert env.unwrapped.episode.scenario == ep.scenario
    assert any(_missing(ep.y).any() for ep in batch)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"detection_dropout": "gilbert"}, ValueError, "detection_dropout"),
    ({"detection_dropout": 1}, TypeError, "detection_dropout"),
    ({"detection_dropout": "runs", "miss_rate_range": (0.1, 0.96)}, ValueError, r"miss_rate_range\[1\]"),
    ({"detection_dropout": "runs", "miss_rate_range": (0.5, 0.1)}, ValueError, "miss_rate_range"),
    ({"detection_dropout": "runs", "miss_rate_range": 0.3}, TypeError, "miss_rate_range"),
    ({"detection_dropout": "runs", "miss_run_range": (0.5, 2.0)}, ValueError, r"miss_run_range\[0\]"),
    ({"detection_dropout": "runs", "miss_run_range": (1.0, 1001.0)}, ValueError, r"miss_run_range\[1\]"),
    ({"detection_dropout": "runs", "miss_run_range": (1.0, float("nan"))}, ValueError, r"miss_run_range\[1\]"),
    ({"outlier_rate_range": (0.0, 0.6)}, ValueError, r"outlier_rate_range\[1\]"),
    ({"outlier_rate_range": (-0.1, 0.1)}, ValueError, r"outlier_rate_range\[0\]"),
    ({"outlier_rate_range": ("0", 0.1)}, TypeError, r"outlier_rate_range\[0\]"),
    ({"miss_rate_range": (0.1, 0.2)}, ValueError, "miss_rate_range=.*detection_dropout='none'"),
    ({"detection_dropout": "bernoulli", "miss_run_range": (2.0, 3.0)}, ValueError, "miss_run_range=.*'runs'"),
    ({"source": "video", "detection_dropout": "bernoulli"}, ValueError, "detection_dropout=.*source='video'"),
    ({"source": "video", "outlier_rate_range": (0.0, 0.1)}, ValueError, "outlier_rate_range=.*source='video'"),
    ({"source": "mot", "detection_dropout": "runs"}, ValueError, "detection_dropout=.*source='mot'"),
    ({"source": "mot", "outlier_rate_range": (0.1, 0.1)}, ValueError, "outlier_rate_range=.*source='mot'"),
])
def test_bad_settings_are_refused_by_name(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        EnvConfig(**kwargs)
    with pytest.raises(error, match=match):
        gym.make(TUNE, **kwargs)


@needs_otb
@pytest.mark.parametrize("kwargs", [{"source": "otb"}, {"source": "otb_tracker", "trackers": ("SiamFC", "MEEM")},
                                    {"source": "otb", "otb_speedup_max": 4},
                                    {"source": "mix", "trackers": ("SiamFC", "MEEM")}])
def test_otb_episodes_get_errors_and_a_nominal_from_what_is_left(kwargs: dict) -> None:
    cfg = EnvConfig(otb_root=OTB_ROOT, **kwargs)
    plain = make_source(cfg).draw_many(SEEDS)
    errs = make_source(EnvConfig(otb_root=OTB_ROOT, **kwargs, **RUNS)).draw_many(SEEDS)
    for a, b in zip(plain, errs, strict=False):
        np.testing.assert_array_equal(b.truth, a.truth)
        assert b.meta == a.meta and {"miss_rate", "miss_run", "outlier_rate"} <= b.scenario.keys()
        assert _missing(b.y).sum() >= _missing(a.y).sum()
        measured = np.flatnonzero(~_missing(a.y))
        assert not _missing(b.y)[[measured[0], measured[-1]]].any()
        if b.meta.get("source", cfg.source) != "sim":
            scale = np.sqrt(np.nanmedian(np.where((b.y[:, 2] > 0) & (b.y[:, 3] > 0), b.y[:, 2] * b.y[:, 3], np.nan)))
            assert b.nominal.sigma_v == pytest.approx(cfg.otb_sigma_v_rel * scale, rel=1e-12)


@needs_otb
def test_the_batched_env_draws_the_single_envs_otb_episodes_with_dropout() -> None:
    kwargs = {"backend": "ufir_cmn", "source": "mix", "otb_root": OTB_ROOT, **RUNS}
    venv = envs.make_vec(TUNE, 6, **kwargs)
    obs, infos = venv.reset(seed=2)
    actions = np.zeros((6, 2), np.float32)
    _, rewards, *_ = venv.step(actions)
    single_obs, single_rewards, _ = _single_steps(kwargs, _tracks(infos, 6), actions)
    np.testing.assert_allclose(obs, single_obs, rtol=1e-6)
    np.testing.assert_allclose(rewards, single_rewards, rtol=1e-9, atol=1e-12)
