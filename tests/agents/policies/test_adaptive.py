"""Sage–Husa adaptive KF: reduces to the KF without adaptation, handles missing data, per-track arrays."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.agents.policies.adaptive import SageHusaConfig, sage_husa_positions
from bboxtune.envs.data.simulate import Scenario, simulate

RNG = np.random.default_rng(1)
Y = np.cumsum(RNG.normal(size=(3, 120, 4)), axis=1) + RNG.normal(size=(3, 120, 4))


def test_without_adaptation_it_is_the_kalman_filter() -> None:
    y = Y.copy()
    y[0, 7] = np.nan
    y[1, :3] = np.nan
    ref = filters.make("kf", filters.constant_velocity(0.05, ndim=4), sigma_w=30.0, sigma_v=2.0).run(y)[..., :4]
    got = sage_husa_positions(y, 0.05, 30.0, 2.0, SageHusaConfig(burn_in=10**6))
    np.testing.assert_allclose(got, ref, atol=1e-8, equal_nan=True)


def test_missing_frames_start_and_gaps() -> None:
    y = Y.copy()
    y[1, :5] = np.nan
    y[2, 50:60] = np.nan
    out = sage_husa_positions(y, 0.05, 10.0, 1.0)
    assert np.isnan(out[1, :5]).all() and np.isfinite(out[1, 5:]).all()
    assert np.isfinite(out[0]).all() and np.isfinite(out[2]).all()


def test_per_track_arrays_equal_separate_runs() -> None:
    tau, sw, sv = np.array([0.03, 0.05, 0.1]), np.array([5.0, 20.0, 60.0]), np.array([0.5, 2.0, 4.0])
    batched = sage_husa_positions(Y, tau, sw, sv)
    for b in range(3):
        np.testing.assert_allclose(batched[b], sage_husa_positions(Y[b:b + 1], tau[b], sw[b], sv[b])[0], rtol=1e-12)


def test_adapts_to_a_measurement_noise_ten_times_the_nominal() -> None:
    scenario = Scenario(psi=0.0, sigma_w=20.0, sigma_xi=5.0, tau=0.05, n_frames=2000, ndim=1)
    track = simulate(scenario, np.random.default_rng(0))
    err = lambda est: np.sqrt(np.mean((est[0] - track.truth)[200:] ** 2))  # noqa: E731
    fixed = sage_husa_positions(track.y[None], 0.05, 20.0, 0.5, SageHusaConfig(burn_in=10**6))
    adapted = sage_husa_positions(track.y[None], 0.05, 20.0, 0.5, SageHusaConfig(b=0.99))
    assert err(adapted) < 0.97 * err(fixed)  # a small gain only: R̂ converges, σ̂_w drifts up (module docstring)


@pytest.mark.parametrize("kwargs, match", [({"tau": -1.0}, "tau"), ({"sigma_v": np.array([1.0, 0.0, 1.0])}, "sigma_v")])
def test_bad_parameters_raise(kwargs: dict, match: str) -> None:
    args = {"tau": 0.05, "sigma_w": 1.0, "sigma_v": 1.0, **kwargs}
    with pytest.raises(ValueError, match=match):
        sage_husa_positions(Y, **args)


@pytest.mark.parametrize("field, value", [("b", 1.0), ("burn_in", 0), ("floor", 0.0)])
def test_bad_config_raises(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        SageHusaConfig(**{field: value})
