from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from bboxtune.envs.data.scenario_ranges import ScenarioRanges
from bboxtune.envs.data.sim_motion import OTB_MOTION, reflect
from bboxtune.envs.data.simulate import PRESETS, Scenario, simulate, simulate_each


def _bounce(x: float, low: float, high: float) -> tuple[float, float]:
    """Reflect ``x`` at the walls one bounce at a time: the folded value and the sign of its velocity."""
    sign = 1.0
    while not low <= x <= high:
        x, sign = (2 * high - x if x > high else 2 * low - x), -sign
    return x, sign


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
    if M == 4:  # log sizes reflected at the size bounds, one frame and coordinate at a time
        for n in range(T):
            for c in (2, 3):
                P[n, c], sign = _bounce(P[n, c], math.log(s.size_bounds[0] / x0[c]), math.log(s.size_bounds[1] / x0[c]))
                V[n, c] *= sign
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
        Scenario(psi=0.5, sigma_w=20.0, sigma_xi=3.0, n_frames=400, ndim=4, sigma_w_log_size=2.0,  # many bounces
                 size_bounds=(25.0, 50.0), x0=(100.0, 80.0, 40.0, 30.0, 5.0, -3.0, 20.0, -10.0)),
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
    for i, (s, track) in enumerate(zip(scenarios, each, strict=False)):
        alone = simulate(s, np.random.default_rng(i))
        for got, want in zip(track, alone, strict=False):  # bit-identical, not just close: episodes are pure functions of seeds
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
        ({"size_bounds": (10.0, 10.0)}, "size_bounds"),
        ({"size_bounds": (0.0, 10.0)}, "size_bounds"),
        ({"size_bounds": (5.0, float("inf"))}, "size_bounds"),
        ({"size_bounds": (100.0, 200.0)}, "x0"),  # the default 64×48 box lies outside
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


def _sample_one_draw_each(ranges: ScenarioRanges, rng: np.random.Generator) -> Scenario:
    """ScenarioRanges.sample as one ``rng.uniform`` call per field (what sample draws in one call)."""
    def draw(bounds: tuple[float, float], log: bool) -> float:
        lo, hi = (math.log(bounds[0]), math.log(bounds[1])) if log else bounds
        value = float(rng.uniform(lo, hi)) if hi > lo else float(lo)
        return math.exp(value) if log else value
    size = [draw(ranges.size, True), draw(ranges.size, True)] if ranges.ndim == 4 else []
    psi, sigma_w, sigma_xi, tau = draw(ranges.psi, False), draw(ranges.sigma_w, True), draw(ranges.sigma_xi, True), \
        draw(ranges.tau, False)
    n_frames = int(rng.integers(ranges.n_frames[0], ranges.n_frames[1], endpoint=True))
    scenario = Scenario(psi=psi, sigma_w=sigma_w, sigma_xi=sigma_xi, tau=tau, n_frames=n_frames, ndim=ranges.ndim,
                        delta=draw(ranges.delta, False), x0=(320.0, 240.0, *size, 0.0, 0.0, 0.0, 0.0) if size else None,
                        size_bounds=ranges.size_bounds)
    if ranges.motion == "otb":
        velocity_rms, size_rw = OTB_MOTION.sample_levels(rng)
        scenario = replace(scenario, motion="otb", velocity_rms=velocity_rms, size_rw=size_rw)
    return scenario


@pytest.mark.parametrize("ranges", [ScenarioRanges(), ScenarioRanges(n_frames=(500, 500), delta=(0.0, 0.02)),
                                    ScenarioRanges(psi=(0.3, 0.3), sigma_w=(2.0, 2.0), ndim=1),
                                    ScenarioRanges(size=(40.0, 40.0), tau=(0.05, 0.05), motion="otb"),
                                    ScenarioRanges(ndim=2, sigma_xi=(1.0, 1.0 + 1e-12))])
def test_scenario_ranges_sample_draws_what_one_uniform_per_field_draws(ranges: ScenarioRanges) -> None:
    """One ``rng.random`` call for the uniform fields gives the same scenarios, bit for bit, and leaves the generator
    where one call per field leaves it."""
    for seed in range(200):
        a, b = np.random.default_rng(seed), np.random.default_rng(seed)
        assert ranges.sample(a) == _sample_one_draw_each(ranges, b)
        assert a.random() == b.random()


@pytest.mark.parametrize(
    "kwargs, field",
    [({"psi": (0.0, 1.0)}, "psi"), ({"sigma_w": (0.0, 1.0)}, "sigma_w"), ({"tau": (0.1, 0.05)}, "tau"),
     ({"n_frames": (1, 10)}, "n_frames"), ({"ndim": 5}, "ndim"), ({"size": (2.0, 200.0)}, "size_bounds")],
)
def test_scenario_ranges_reject_bad_ranges(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ScenarioRanges(**kwargs)


def test_reflect_folds_into_the_interval_and_leaves_inside_values_alone():
    x = np.array([[-7.3, -1.0, 0.0, 0.4, 1.0, 2.5, 9.9]])
    rate = np.arange(7.0)[None] + 1.0
    folded, signed = reflect(x, rate, -1.0, 1.0)
    want = np.array([_bounce(v, -1.0, 1.0) for v in x[0]])
    np.testing.assert_allclose(folded[0], want[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(signed[0], rate[0] * want[:, 1])
    inside = np.array([[-0.5, 0.25]])
    same = reflect(inside, rate[:, :2], -1.0, 1.0)
    assert same[0] is inside and same[1] is not None  # no copy, so untouched tracks stay bit for bit


def test_size_bounds_change_only_tracks_that_reach_them():
    s = replace(PRESETS["seed000_car4"], sigma_w_log_size=0.05)  # sizes 107 × 87 px drift a little
    free = simulate(replace(s, size_bounds=(1e-6, 1e9)), np.random.default_rng(4))
    bounded = simulate(s, np.random.default_rng(4))
    assert 4.0 < free.truth[:, 2:].min() and free.truth[:, 2:].max() < 1000.0  # never reaches (4, 1000) px
    for got, want in zip(bounded, free, strict=False):
        np.testing.assert_array_equal(got, want)
    tight = simulate(replace(s, size_bounds=(80.0, 120.0)), np.random.default_rng(4))
    assert not np.array_equal(tight.truth, free.truth)
    assert tight.truth[:, 2:].min() >= 80.0 - 1e-9 and tight.truth[:, 2:].max() <= 120.0 + 1e-9
    np.testing.assert_array_equal(tight.truth[:, :2], free.truth[:, :2])  # centres are not affected


@pytest.mark.parametrize("n_frames", [10_000, 100_000])
def test_long_tracks_keep_sizes_within_the_bounds(n_frames):
    """Unbounded, a 10,000-frame track at τ = 0.1 s reached 1e13 px; reflected, every size stays within
    (4, 1000) px and every value is finite, at the env's longest track too."""
    s = Scenario(psi=0.9, sigma_w=100.0, sigma_xi=10.0, tau=0.1, n_frames=n_frames, ndim=4, x0=(320, 240, 200, 20, 0, 0, 0, 0))
    tr = simulate(s, np.random.default_rng(0), n_tracks=2)
    sizes = tr.truth[..., 2:]
    assert np.isfinite(tr.y).all() and np.isfinite(tr.truth_state).all()
    assert sizes.min() >= 4.0 * (1 - 1e-12) and sizes.max() <= 1000.0 * (1 + 1e-12)
    assert sizes.max() > 500.0 and sizes.min() < 8.0  # long enough to bounce: the bounds are doing the work


def test_default_env_tracks_never_reach_the_size_bounds():
    """The default 500-frame env episodes (published results) are the free tracks, bit for bit: over the first
    1,000 noise seeds and the 500 test seeds, widening the bounds to the widest allowed changes nothing."""
    from bboxtune.envs.episodes.config import EnvConfig
    from bboxtune.envs.episodes.sources import SimSource

    seeds = list(range(1000)) + [10**9 + i for i in range(500)]
    default = SimSource(EnvConfig()).draw_many(seeds)
    free = SimSource(EnvConfig(box_size_bounds=(1.0, 1e5))).draw_many(seeds)
    for a, b in zip(default, free, strict=False):
        np.testing.assert_array_equal(a.y, b.y)
        np.testing.assert_array_equal(a.truth, b.truth)
    sizes = np.stack([ep.truth[:, 2:] for ep in default])
    assert 4.0 < sizes.min() and sizes.max() < 1000.0
