"""bboxtune/FilterRetune-v0: episodes of at least two windows (short OTB sequences), rejected calls."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs  # noqa: F401  (registers the ids)
from tests.envs.conftest import OTB_ROOT, needs_otb

RETUNE, TUNE = "bboxtune/FilterRetune-v0", "bboxtune/FilterTune-v0"


@needs_otb
@pytest.mark.parametrize("split, short", [("train", {"Bird2"}), ("test", {"Deer", "Football1", "KiteSurf", "Skiing"})])
def test_otb_sequences_shorter_than_two_windows_are_left_out(split: str, short: set[str]) -> None:
    """Before, drawing one of these (99 frames or fewer with window=50) crashed training at random."""
    env = gym.make(RETUNE, source="otb", otb_root=OTB_ROOT, split=split, backend="ufir_cmn")
    tune = gym.make(TUNE, source="otb", otb_root=OTB_ROOT, split=split, backend="ufir_cmn")
    first_picks, redrawn = set(), 0
    for noise_seed in range(150):
        _, info = env.reset(options={"noise_seed": noise_seed})
        name = info["track"]["sequence"]
        assert name not in short and len(env.unwrapped.episode.y) >= 100
        first = tune.reset(options={"noise_seed": noise_seed})[1]["track"]["sequence"]  # the uniform first pick
        first_picks.add(first)
        if first in short:
            redrawn += 1
        else:
            assert name == first  # a seed whose first pick is long enough keeps its sequence
    assert redrawn > 0 and first_picks & short  # the rule was exercised
    for name in short:
        with pytest.raises(ValueError, match=rf"{name}.* has \d+ frames"):
            env.reset(options={"sequence": name, "noise_seed": 1})
    obs, _ = env.reset(options={"noise_seed": 0})  # still usable after the rejected resets
    assert obs.shape == env.observation_space.shape


@pytest.mark.parametrize("kwargs", [{"track_length": 99, "window": 50}, {"track_length": 8, "window": 8},
                                    {"track_length": 60, "window": 40, "source": "video", "detector": "regions"}])
def test_track_length_below_two_windows_is_refused_at_construction(kwargs: dict) -> None:
    with pytest.raises(ValueError, match=r"track_length=\d+ is too short.*window"):
        gym.make(RETUNE, **kwargs)
    gym.make(RETUNE, **{**kwargs, "track_length": 2 * kwargs["window"]}).reset(seed=0)  # exactly 2 windows: fine


def test_a_rejected_reset_or_step_mid_episode_changes_nothing() -> None:
    actions = np.random.default_rng(0).uniform(-1, 1, (5, 2)).astype(np.float32)

    def run(interrupt: bool) -> list:
        env = gym.make(RETUNE, track_length=300, window=50)
        out = [env.reset(seed=3)[0]]
        for i, a in enumerate(actions):
            if interrupt and i == 2:
                for bad in ({"noise_seed": -1}, {"noise_seed": "abc"}, {"sequence": "Car4"}, {"bogus": 1}):
                    with pytest.raises((ValueError, TypeError)):
                        env.reset(seed=7, options=bad)
                with pytest.raises(ValueError, match="action"):
                    env.step(np.stack([a, a]))
            obs, reward, terminated, _, info = env.step(a)
            out += [obs, reward, info["rmse"], info["window"], terminated]
        out.append(env.reset()[0])  # np_random, too, is as it was: the next unpinned episode is the same
        return out

    for got, want in zip(run(True), run(False), strict=True):
        np.testing.assert_array_equal(got, want)


def test_step_after_the_last_window_raises_and_reset_recovers() -> None:
    env = gym.make(RETUNE, track_length=100, window=50)
    with pytest.raises(RuntimeError, match="reset"):
        env.unwrapped.step(np.zeros(2, np.float32))  # before any reset
    env.reset(seed=0)
    *_, terminated, _, info = env.step(np.zeros(2, np.float32))
    assert terminated and info["window"] == (50, 100) and "scenario" in info
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2, np.float32))
    env.reset()
    assert env.step(np.zeros(2, np.float32))[2]  # a new 2-window episode: its one step ends it


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn"])
def test_features_so_far_grow_into_the_one_shot_observation_of_the_whole_track(backend: str) -> None:
    """features_so_far() is the FilterTune-v0 observation of the frames filtered so far: after the last window it is
    exactly FilterTune-v0's observation of the same episode, and before it, that of the track cut at window_start."""
    kwargs = dict(backend=backend, scenario="nonstationary", track_length=120, window=40)
    env, tune = gym.make(RETUNE, **kwargs), gym.make(TUNE, **kwargs)
    env.reset(options={"noise_seed": 3})
    first = env.unwrapped.features_so_far()
    assert first[-1] == pytest.approx(np.log(40))  # the last feature is log(frames seen)
    while not env.step(np.zeros(env.action_space.shape, np.float32))[2]:
        pass
    whole, _ = tune.reset(options={"noise_seed": 3})
    np.testing.assert_array_equal(env.unwrapped.features_so_far(), whole)
    assert not np.array_equal(first, whole)
    with pytest.raises(RuntimeError, match="reset"):
        gym.make(RETUNE).unwrapped.features_so_far()


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn"])
def test_offline_view_adds_the_coming_window_and_the_whole_track(backend: str) -> None:
    """retune_view="offline": the causal observation, then FEATURE_NAMES of the coming window's measurements (the
    rule's estimates as pilot) and of the whole track (= FilterTune-v0's observation); zeros for the coming window
    in the terminal observation. The causal part is the default observation, unchanged."""
    from bboxtune.envs.episodes.features import FEATURE_NAMES, measurement_features

    kwargs = dict(backend=backend, scenario="nonstationary", track_length=105, window=25)  # a last window of 5 frames
    offline, causal = gym.make(RETUNE, retune_view="offline", **kwargs), gym.make(RETUNE, **kwargs)
    n = len(FEATURE_NAMES)
    assert offline.observation_space.shape[0] == causal.observation_space.shape[0] + 2 * n
    obs, _ = offline.reset(options={"noise_seed": 5})
    base, _ = causal.reset(options={"noise_seed": 5})
    whole, _ = gym.make(TUNE, **kwargs).reset(options={"noise_seed": 5})
    u = offline.unwrapped
    ep, rule = u.episode, u.rule_estimates
    done = False
    while True:
        np.testing.assert_array_equal(obs[: len(base)], base)
        np.testing.assert_array_equal(obs[-n:], whole)
        start = u.window_start
        coming = obs[len(base): len(base) + n]
        if done:
            assert start == len(ep.y) and not coming.any()
            break
        end = min(start + 25, len(ep.y))
        expected = measurement_features(ep.y[start:end], ep.tau, ep.nominal.sigma_v, ep.nominal.sigma_w, rule[start:end])
        np.testing.assert_allclose(coming, expected.astype(np.float32))
        assert np.isfinite(obs).all()
        action = offline.action_space.sample()
        obs, _, done, _, _ = offline.step(action)
        base = causal.step(action)[0]


@pytest.mark.parametrize(("backend", "view"), [("ufir_cmn", "causal"), ("kf_cmn", "offline")])
def test_observation_names_match_the_observation(backend: str, view: str) -> None:
    """One distinct name per entry, in the Observation Space table's order: the current action's entries are the
    action itself (the rule's after the warm-up), the progress the share filtered, the whole track's part
    FilterTune-v0's observation."""
    from bboxtune.envs.episodes.features import FEATURE_NAMES

    env = gym.make(RETUNE, backend=backend, scenario="nonstationary", track_length=100, window=20, retune_view=view)
    names = env.unwrapped.observation_names
    assert len(names) == env.observation_space.shape[0] == len(set(names))
    obs, _ = env.reset(options={"noise_seed": 3})
    action = env.action_space.sample()
    obs, _, _, _, _ = env.step(action)
    at = {n: obs[i] for i, n in enumerate(names)}
    tuned = [n for n in names if n.startswith("action_")]
    assert len(tuned) == len(action) and [at[n] for n in tuned] == pytest.approx(action)
    assert at["progress"] == pytest.approx(40 / 100) and names[: len(FEATURE_NAMES)] == FEATURE_NAMES
    if view == "offline":
        whole, _ = gym.make(TUNE, backend=backend, scenario="nonstationary", track_length=100).reset(options={"noise_seed": 3})
        np.testing.assert_array_equal([at[f"track_{n}"] for n in FEATURE_NAMES], whole)


def test_offline_view_is_measurement_only() -> None:
    """The offline observations of an episode do not change when its ground truth (and true scenario) do."""
    from dataclasses import replace

    kwargs = dict(scenario="nonstationary", track_length=100, window=20, retune_view="offline")
    envs_ = [gym.make(RETUNE, **kwargs) for _ in range(2)]
    seen = []
    for k, env in enumerate(envs_):
        obs, _ = env.reset(options={"noise_seed": 9})
        u = env.unwrapped
        if k:
            u.episode = replace(u.episode, truth=u.episode.truth * 3.0 + 500.0, scenario={})
        rows, done = [obs], False
        while not done:
            obs, _, done, _, _ = env.step(np.full(env.action_space.shape, 0.3, np.float32))
            rows.append(obs)
        seen.append(np.array(rows))
    np.testing.assert_array_equal(seen[0], seen[1])


def test_retune_view_is_checked() -> None:
    with pytest.raises(ValueError, match="retune_view.*'causal', 'offline'"):
        gym.make(RETUNE, retune_view="future")


def test_hold_missing_shows_the_last_estimate() -> None:
    from bboxtune.envs.episodes.scoring import hold_missing

    est = np.arange(2 * 5 * 4, dtype=float).reshape(2, 5, 4)
    est[0, 0], est[0, 2:4], est[1, :2] = np.nan, np.nan, np.nan
    np.testing.assert_array_equal(hold_missing(est)[..., 0], [[np.nan, 4, 4, 4, 16], [np.nan, np.nan, 28, 32, 36]])
    np.testing.assert_array_equal(hold_missing(est, np.full(4, -1.0))[:, :2, 1], [[-1, 5], [-1, -1]])
    np.testing.assert_array_equal(hold_missing(est, np.full(4, np.nan)), hold_missing(est))
    clean = np.ones((1, 3, 4))
    assert hold_missing(clean) is clean


def test_a_gap_longer_than_the_horizon_is_scored_with_the_last_estimate_held() -> None:
    """A sim episode whose gap covers frames 1–20 (only frame 0 measured before it): the shortest horizon has no
    estimate there; the window is scored with the warm-up's last estimate held, so the reward is finite (it was
    NaN — every frame of the track so far left out — and crashed PPO training) and, as the rule's, covers every
    frame with ground truth."""
    env = gym.make(RETUNE, scenario="nonstationary", window=10)
    env.reset(options={"noise_seed": 2091389876304249611})
    u = env.unwrapped
    assert [1, 21] in [list(g) for g in u.episode.scenario["gaps"]]
    shortest = -np.ones(env.action_space.shape, np.float32)
    assert u.physical(u.action_map.to_params(shortest[None], u.episode.nominal))["horizon"] <= 10
    _, reward, *_ , info = env.step(shortest)
    assert np.isfinite(reward) and np.isfinite(info["rmse"])
    est = u.estimates
    assert np.isfinite(est[:20]).all()
    np.testing.assert_array_equal(est[10:20], np.broadcast_to(est[9], (10, 4)))  # held through the gap
