"""bboxtune/FilterRetune-v0: episodes of at least two windows (short OTB sequences), rejected calls."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
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
