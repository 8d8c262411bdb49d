"""scenario="nonstationary": regime switches, manoeuvre bursts and gaps within a track (bboxtune.envs.data.sim_regimes)."""

from __future__ import annotations

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs  # noqa: F401  (registers the ids)
from bboxtune.envs.data.sim_regimes import REGIMES, simulate_nonstationary
from bboxtune.envs.data.simulate import Scenario
from bboxtune.envs.episodes.config import EnvConfig

TUNE, RETUNE = "bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"


def _episode(seed: int, **kwargs):
    env = gym.make(TUNE, scenario="nonstationary", **kwargs)
    env.reset(options={"noise_seed": seed})
    return env.unwrapped.episode


@pytest.mark.parametrize("seed", range(12))
def test_schedule_is_consistent_with_the_track(seed: int) -> None:
    ep = _episode(seed)
    sc, T = ep.scenario, len(ep.y)
    regimes = sc["regimes"]
    assert regimes[0]["start"] == 0 and regimes[-1]["end"] == T
    assert all(a["end"] == b["start"] for a, b in zip(regimes, regimes[1:], strict=False))  # they tile the track
    assert REGIMES.noise_switches[0] <= len(regimes) - 1 <= REGIMES.noise_switches[1]
    assert all(T // 10 <= r["start"] < T - T // 10 for r in regimes[1:])
    assert all(0.0 <= r["psi"] <= 0.95 and 0.5 <= r["sigma_xi"] <= 10.0 for r in regimes)
    missing = ~np.isfinite(ep.y).all(axis=1)
    expected = np.zeros(T, bool)
    for start, end in sc["gaps"]:
        expected[start:end] = True
    np.testing.assert_array_equal(missing, expected)  # the gaps, and nothing else, are missing
    assert np.isfinite(ep.truth).all() and not missing[0]
    for start, end in sc["manoeuvres"]:
        assert 1 <= start < end <= T and end - start <= REGIMES.manoeuvre_frames[1]
    frames = np.array([r["end"] - r["start"] for r in regimes])
    assert sc["psi"] == pytest.approx(np.sum(frames * [r["psi"] for r in regimes]) / T)


def test_the_first_regime_is_the_stationary_episodes_draw_and_the_default_is_unchanged() -> None:
    stationary = gym.make(TUNE)
    for seed in range(5):
        stationary.reset(options={"noise_seed": seed})
        st = stationary.unwrapped.episode
        ns = _episode(seed)
        first = ns.scenario["regimes"][0]
        assert (first["psi"], first["sigma_xi"], ns.scenario["sigma_w"]) == (st.scenario["psi"], st.scenario["sigma_xi"],
                                                                            st.scenario["sigma_w"])
        assert ns.tau == st.tau and ns.truth[0].tolist() == st.truth[0].tolist()
        assert not np.array_equal(ns.y, st.y)  # its own noise
        assert "regimes" not in st.scenario


def test_episodes_are_reproducible_and_the_schedule_stays_out_of_the_observation() -> None:
    a, b = gym.make(TUNE, scenario="nonstationary"), gym.make(TUNE, scenario="nonstationary")
    oa, ia = a.reset(options={"noise_seed": 7})
    ob, _ = b.reset(seed=3)
    ob, ib = b.reset(options={"noise_seed": 7})
    np.testing.assert_array_equal(oa, ob)
    assert ia == ib and "scenario" not in ia and "regimes" not in str(ia)
    _, _, _, _, info = a.step(np.zeros(2, np.float32))
    assert {"regimes", "manoeuvres", "gaps"} <= set(info["scenario"])
    retune = gym.make(RETUNE, scenario="nonstationary")
    retune.reset(options={"noise_seed": 7})
    infos, done = [], False
    while not done:
        _, _, done, _, info = retune.step(np.zeros(2, np.float32))
        infos.append(info)
    assert all("scenario" not in i for i in infos[:-1]) and infos[-1]["scenario"]["regimes"] == info["scenario"]["regimes"]


def test_noise_follows_each_regime() -> None:
    """Within each regime the CMN has the regime's lag-1 correlation ψ and stationary variance σ_ξ²/(1 − ψ²)
    (measured over many tracks, away from the switch); manoeuvres raise the centre's acceleration."""
    base = Scenario(psi=0.2, sigma_w=5.0, sigma_xi=1.0, tau=0.05, n_frames=400, ndim=4)
    noise, accel_in, accel_out = {0: [], 1: []}, [], []
    no_gaps = replace(REGIMES, gaps=(0, 0))
    for seed in range(300):
        track, sc = simulate_nonstationary(base, seed, (0.9, 0.9), (4.0, 4.0), no_gaps)
        v = track.y[:, 0] - track.truth[:, 0]
        r = sc["regimes"]
        noise[0].append(v[10:r[0]["end"]])
        noise[1].append(v[r[1]["start"] + 30:r[1]["end"]])  # the regime ψ = 0.9, σ_ξ = 4 after its transient
        a = np.diff(np.diff(track.truth[:, 0]))
        inside = np.zeros(len(a), bool)
        for start, end in sc["manoeuvres"]:
            inside[max(start - 1, 0):end - 2] = True
        accel_in.append(a[inside])
        accel_out.append(a[~inside])
    for k, (psi, sigma_xi) in enumerate([(0.2, 1.0), (0.9, 4.0)]):
        x = noise[k]
        var = np.mean(np.concatenate([s**2 for s in x]))
        acf = np.sum(np.concatenate([s[1:] * s[:-1] for s in x])) / np.sum(np.concatenate([s[1:] ** 2 for s in x]))
        assert var == pytest.approx(sigma_xi**2 / (1 - psi**2), rel=0.1)
        assert acf == pytest.approx(psi, abs=0.03)
    ratio = np.std(np.concatenate(accel_in)) / np.std(np.concatenate(accel_out))
    assert 7.0 < ratio < 11.0  # σ_w × 10 inside the bursts


@pytest.mark.parametrize("kwargs", [{"source": "otb"}, {"source": "video"}, {"motion": "otb"}])
def test_nonstationary_is_refused_where_it_would_not_apply(kwargs: dict) -> None:
    with pytest.raises(ValueError, match="scenario='nonstationary'.*allowed only with source 'sim' or 'mix'"):
        EnvConfig(scenario="nonstationary", **kwargs)
    with pytest.raises(ValueError, match="scenario='bursty'; allowed: one of"):
        EnvConfig(scenario="bursty")
    with pytest.raises(TypeError, match="scenario=1"):
        EnvConfig(scenario=1)


def test_short_tracks_still_work() -> None:
    env = gym.make(TUNE, scenario="nonstationary", track_length=8)
    for seed in range(20):
        env.reset(options={"noise_seed": seed})
        _, reward, *_ = env.step(np.zeros(2, np.float32))
        assert np.isfinite(reward) or not np.isfinite(env.unwrapped.episode.y).any()
