from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from envs.simulate import PRESETS, Scenario, ScenarioRanges, simulate, simulate_each


def reference_loop(s: Scenario, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame-by-frame x_n = F(τ+δ) x_{n−1} + B(τ) w_n and v_n = ψ v_{n−1} + ξ_n, with the same random draws
    (same order and shapes) as the vectorised simulator; boxes evolve log sizes."""
    rng = np.random.default_rng(seed)
    M, T, tau, h = s.M, s.n_frames, s.tau, s.tau + s.delta
    x0 = s.initial_state
    sig = np.full(M, s.sigma_w)
    p, v = x0[:M].copy(), x0[M:].copy()
    if M == 4:
        sig[2:] = s.sigma_w_log_size
        v[2:] = v[2:] / p[2:]
        p[2:] = 0.0
    w = rng.standard_normal((1, T - 1, M))[0] * sig
    F = np.array([[1.0, h], [0.0, 1.0]])
    B = np.array([tau**2 / 2, tau])
    P, V = [p.copy()], [v.copy()]
    for n in range(1, T):
        for c in range(M):
            p[c], v[c] = F @ np.array([p[c], v[c]]) + B * w[n - 1, c]
        P.append(p.copy())
        V.append(v.copy())
    P, V = np.array(P), np.array(V)
    sxi = np.full(M, s.sigma_xi)
    if M == 4:
        P[:, 2:] = x0[2:4] * np.exp(P[:, 2:])
        V[:, 2:] = P[:, 2:] * V[:, 2:]
        sxi[2:] *= s.size_noise_ratio
    xi = rng.standard_normal((1, T, M))[0] * sxi
    cmn = np.empty_like(xi)
    cmn[0] = xi[0] / math.sqrt(1 - s.psi**2)
    for n in range(1, T):
        cmn[n] = s.psi * cmn[n - 1] + xi[n]
    return P, np.hstack([P, V]), P + cmn


@pytest.mark.parametrize(
    "scenario",
    [
        Scenario(psi=0.7, sigma_w=3.0, sigma_xi=2.0, n_frames=60, ndim=1, x0=(1.0, 1.0)),
        Scenario(psi=0.0, sigma_w=5.0, sigma_xi=1.0, n_frames=40, ndim=2, delta=0.02, x0=(5.0, 6.0, 1.0, -2.0)),
        Scenario(psi=0.9, sigma_w=20.0, sigma_xi=3.0, n_frames=50, ndim=4, sigma_w_log_size=0.5,
                 x0=(100.0, 80.0, 40.0, 30.0, 5.0, -3.0, 2.0, -1.0)),
        replace(PRESETS["seed004_delta10"], n_frames=30),
    ],
)
def test_vectorised_simulator_equals_frame_by_frame_model(scenario):
    truth, state, y = reference_loop(scenario, seed=7)
    track = simulate(scenario, np.random.default_rng(7))
    np.testing.assert_allclose(track.truth, truth, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(track.truth_state, state, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(track.y, y, rtol=1e-10, atol=1e-9)
    assert track.tau == scenario.tau


@pytest.mark.parametrize("ndim", [1, 2, 4])
def test_simulate_each_equals_simulating_one_at_a_time(ndim):
    ranges = ScenarioRanges(n_frames=(300, 300), delta=(0.0, 0.01), ndim=ndim)
    scenarios = [ranges.sample(np.random.default_rng(100 + i)) for i in range(5)]
    scenarios[2] = replace(scenarios[2], psi=0.0)  # white noise: no filtering of ξ
    each = simulate_each(scenarios, [np.random.default_rng(i) for i in range(5)])
    for i, (s, track) in enumerate(zip(scenarios, each)):
        alone = simulate(s, np.random.default_rng(i))
        for got, want in zip(track, alone):  # bit-identical, not just close: episodes are pure functions of seeds
            np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError, match="equal n_frames"):
        simulate_each([scenarios[0], replace(scenarios[1], n_frames=301)], [np.random.default_rng(0)] * 2)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_shapes_first_frame_and_reproducibility(name):
    s = PRESETS[name]
    a, b = simulate(s, np.random.default_rng(1)), simulate(s, np.random.default_rng(1))
    c = simulate(s, np.random.default_rng(2))
    assert a.truth.shape == a.y.shape == (s.n_frames, s.M) and a.truth_state.shape == (s.n_frames, s.K)
    np.testing.assert_array_equal(a.y, b.y)
    assert not np.allclose(a.y, c.y)
    np.testing.assert_array_equal(a.truth_state[0], s.initial_state)  # frame 0 is x0 exactly (P0 = 0)
    np.testing.assert_array_equal(a.truth_state[:, : s.M], a.truth)  # positions first
    if s.ndim == 4:
        assert np.all(a.truth[:, 2:] > 0)


def test_presets_follow_the_papers():
    s = PRESETS["seed000_two_state"]
    assert (s.sigma_w, s.sigma_xi, s.tau, s.n_frames, s.ndim, s.x0) == (50.0, 4.0, 0.05, 2000, 1, (1.0, 1.0))
    car4 = PRESETS["seed000_car4"]
    assert (car4.tau, car4.sigma_w, car4.sigma_xi, car4.psi) == (0.05, 3.0, 2.0, 0.9)
    suv = PRESETS["seed001_suv"]
    assert round(math.sqrt(12 * suv.sigma_xi / (suv.tau**2 * suv.sigma_w))) == 49  # the paper's N_opt
    assert (PRESETS["seed004_delta0"].delta, PRESETS["seed004_delta10"].delta) == (0.0, 10.0)


def test_batch_statistics_match_the_model():
    s = Scenario(psi=0.8, sigma_w=2.0, sigma_xi=3.0, tau=0.1, n_frames=40, ndim=1)
    tr = simulate(s, np.random.default_rng(0), n_tracks=20000)
    assert tr.y.shape == (20000, 40, 1) and tr.truth_state.shape == (20000, 40, 2)
    v = (tr.y - tr.truth)[..., 0]
    stationary = 3.0 / math.sqrt(1 - 0.8**2)
    assert v[:, 0].std() == pytest.approx(stationary, rel=0.03)  # stationary from the first frame
    assert v[:, -1].std() == pytest.approx(stationary, rel=0.03)
    assert np.corrcoef(v[:, 10], v[:, 11])[0, 1] == pytest.approx(0.8, abs=0.02)
    accel = np.diff(tr.truth_state[..., 1], axis=1) / s.tau  # v_n − v_{n−1} = τ w_n
    assert accel.std() == pytest.approx(2.0, rel=0.02)


def test_n_tracks_tracks_are_independent_and_validated():
    tr = simulate(PRESETS["seed000_car4"], np.random.default_rng(0), n_tracks=3)
    assert tr.y.shape == (3, 659, 4)
    assert not np.allclose(tr.y[0], tr.y[1])
    with pytest.raises(ValueError, match="n_tracks"):
        simulate(PRESETS["seed000_car4"], np.random.default_rng(0), n_tracks=0)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"psi": 1.0}, "psi"),
        ({"psi": -0.1}, "psi"),
        ({"sigma_w": 0.0}, "sigma_w"),
        ({"sigma_xi": float("nan")}, "sigma_xi"),
        ({"tau": -1.0}, "tau"),
        ({"ndim": 3}, "ndim"),
        ({"n_frames": 1}, "n_frames"),
        ({"n_frames": 10.5}, "n_frames"),
        ({"delta": -0.05, "tau": 0.05}, "delta"),
        ({"x0": (1.0, 2.0)}, "x0"),
        ({"x0": (1.0, 2.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0)}, "x0"),
        ({"size_noise_ratio": 0.0}, "size_noise_ratio"),
    ],
)
def test_scenario_rejects_bad_values(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Scenario(**kwargs)


def test_scenario_ranges_sample_in_range_and_reproducible():
    ranges = ScenarioRanges(delta=(0.0, 0.01))
    draws = [ranges.sample(np.random.default_rng(i)) for i in range(300)]
    assert draws[5] == ranges.sample(np.random.default_rng(5))
    for s in draws:
        assert 0.0 <= s.psi <= 0.95 and 1.0 <= s.sigma_w <= 100.0 and 0.5 <= s.sigma_xi <= 10.0
        assert 1 / 30 <= s.tau <= 0.05 and 200 <= s.n_frames <= 1000 and 0.0 <= s.delta <= 0.01
        assert 20.0 <= s.x0[2] <= 200.0 and s.ndim == 4
    # log-uniform: about half the σ_w draws fall below the geometric midpoint 10
    assert 0.4 < np.mean([s.sigma_w < 10.0 for s in draws]) < 0.6
    fixed = ScenarioRanges(psi=(0.5, 0.5), ndim=1).sample(np.random.default_rng(0))
    assert fixed.psi == 0.5 and fixed.ndim == 1 and fixed.x0 is None


@pytest.mark.parametrize(
    "kwargs, field",
    [({"psi": (0.0, 1.0)}, "psi"), ({"sigma_w": (0.0, 1.0)}, "sigma_w"), ({"tau": (0.1, 0.05)}, "tau"),
     ({"n_frames": (1, 10)}, "n_frames"), ({"ndim": 5}, "ndim")],
)
def test_scenario_ranges_reject_bad_ranges(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ScenarioRanges(**kwargs)
