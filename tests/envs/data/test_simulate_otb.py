"""The simulator's opt-in "otb" motion model (bboxtune.envs.data.sim_motion): bit-identity and the model's statistics."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from bboxtune.envs.data.scenario_ranges import ScenarioRanges
from bboxtune.envs.data.sim_motion import OTB_MOTION, OTBMotion
from bboxtune.envs.data.simulate import Scenario, simulate, simulate_each
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.sources import SimSource


def test_simulate_each_equals_simulating_one_at_a_time():
    ranges = ScenarioRanges(n_frames=(300, 300), delta=(0.0, 0.01), tau=(1 / 30, 0.1), motion="otb")
    scenarios = [ranges.sample(np.random.default_rng(100 + i)) for i in range(6)]
    assert len({s.velocity_rms for s in scenarios}) == 6 and all(s.motion == "otb" for s in scenarios)
    each = simulate_each(scenarios, [np.random.default_rng(i) for i in range(6)])
    for i, (s, track) in enumerate(zip(scenarios, each, strict=False)):
        for got, want in zip(track, simulate(s, np.random.default_rng(i)), strict=False):  # bit-identical
            np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError, match="motion"):
        simulate_each([scenarios[0], replace(scenarios[1], motion="cv")], [np.random.default_rng(0)] * 2)


def test_env_episodes_are_pure_functions_of_the_seed():
    seeds = [3, 11, 10**9 + 7, 42]
    otb = SimSource(EnvConfig(motion="otb"))
    batch = otb.draw_many(seeds)
    cv = SimSource(EnvConfig()).draw_many(seeds)
    for seed, ep, ep_cv in zip(seeds, batch, cv, strict=False):
        alone = otb.draw(None, seed)
        np.testing.assert_array_equal(ep.y, alone.y)
        np.testing.assert_array_equal(ep.truth, alone.truth)
        assert ep.scenario == alone.scenario and ep.scenario["motion"] == "otb"
        # the same seed draws the same ψ, σ_ξ and τ under both models (the motion levels are drawn after them)
        assert ((ep.tau, ep.scenario["psi"], ep.scenario["sigma_xi"])
                == (ep_cv.tau, ep_cv.scenario["psi"], ep_cv.scenario["sigma_xi"]))
        assert not np.allclose(ep.truth, ep_cv.truth)
        np.testing.assert_array_equal(ep.truth[0], ep_cv.truth[0])  # the same first box
    assert not np.allclose(batch[0].truth, batch[1].truth)


def test_cv_default_is_unchanged_by_the_new_fields():
    a = ScenarioRanges().sample(np.random.default_rng(5))
    assert a.motion == "cv" and a == ScenarioRanges(motion="cv").sample(np.random.default_rng(5))
    assert EnvConfig().motion == "cv"
    with pytest.raises(ValueError, match="motion"):
        EnvConfig(motion="singer")
    with pytest.raises(ValueError, match="motion"):
        Scenario(motion="otb", ndim=2)
    with pytest.raises(ValueError, match="velocity_rms"):
        Scenario(motion="otb", velocity_rms=0.0)
    with pytest.raises(ValueError, match="cruise_share"):
        replace(OTB_MOTION, cruise_share=1.5)


def test_otb_tracks_follow_the_model():
    """Centre increments / box scale have the model's autocovariance τ²σ_r²(c e^{−λkτ} + (1 − c) φ^k); log sizes
    step with std σ_ℓ √τ; manoeuvres (cruise redraws) come at λ per second. 400 tracks of 600 frames, fixed seed."""
    m, tau, level, size_rw = OTB_MOTION, 1 / 30, 1.5, 0.1
    s = Scenario(motion="otb", tau=tau, n_frames=600, ndim=4, velocity_rms=level, size_rw=size_rw,
                 x0=(320.0, 240.0, 60.0, 40.0, 0.0, 0.0, 0.0, 0.0), size_bounds=(1.0, 1e5))
    tr = simulate(s, np.random.default_rng(0), n_tracks=400)
    scale = np.sqrt(tr.truth[..., 2] * tr.truth[..., 3])
    d = np.diff(tr.truth[..., :2], axis=1) / scale[:, :-1, None]
    for k in (0, 1, 3, 10, 30):
        got = np.mean(d[:, k:] * d[:, :d.shape[1] - k])
        want = tau**2 * level**2 * (m.cruise_share * math.exp(-m.switch_rate * k * tau)
                                   + (1 - m.cruise_share) * math.exp(-k * tau / m.jitter_time))
        assert got == pytest.approx(want, rel=0.08, abs=0.01 * tau**2 * level**2), k
    steps = np.diff(np.log(tr.truth[..., 2:]), axis=1)
    assert steps.std() == pytest.approx(size_rw * math.sqrt(tau), rel=0.02)
    # frame-to-frame changes of the velocity beyond the jitter's reach are the manoeuvres
    velocity = tr.truth_state[..., 4:6] / scale[..., None]
    assert np.isfinite(velocity).all() and velocity.std() == pytest.approx(level, rel=0.1)


def test_levels_are_log_normal_with_the_fitted_parameters():
    draws = np.array([OTB_MOTION.sample_levels(np.random.default_rng(i)) for i in range(4000)])
    logs = np.log(draws)
    assert logs[:, 0].mean() == pytest.approx(OTB_MOTION.level_log_mean, abs=0.05)
    assert logs[:, 0].std() == pytest.approx(OTB_MOTION.level_log_std, rel=0.05)
    assert logs[:, 1].mean() == pytest.approx(OTB_MOTION.size_log_mean, abs=0.05)
    assert logs[:, 1].std() == pytest.approx(OTB_MOTION.size_log_std, rel=0.05)
    with pytest.raises(ValueError, match="switch_rate"):
        OTBMotion(switch_rate=0.0, cruise_share=0.5, jitter_time=0.1, level_log_mean=0.0, level_log_std=1.0,
                  size_log_mean=0.0, size_log_std=1.0)
