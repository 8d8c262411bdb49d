"""Action mapping (both directions) and measurement-only features."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.envs.episodes.actions import (
    ACCEPTS,
    BACKENDS,
    DEFAULT_TUNE,
    SIGMA_PARAMETERS,
    STOCK,
    TUNABLE,
    ActionMap,
    Nominal,
    parameter_family,
)
from bboxtune.envs.episodes.features import FEATURE_NAMES, estimate_sigmas, measurement_features

NOMINAL = Nominal(sigma_w=10.0, sigma_v=2.0, psi=0.0, horizon=24)
FULL = ActionMap(tune=("psi", "horizon", "sigma_w", "sigma_v"), K=2, horizon_max=400)


def test_default_tune_is_accepted_by_each_backend() -> None:
    for backend, tune in DEFAULT_TUNE.items():
        assert set(tune) <= set(ACCEPTS[backend])


def test_the_back_ends_of_the_envs() -> None:
    assert BACKENDS == (*filters.NAMES, "bytetrack_kf") and "sort_kf" not in BACKENDS  # sort_kf: nothing to tune
    assert tuple(ACCEPTS) == tuple(DEFAULT_TUNE) == BACKENDS
    assert all(parameter_family(b) == SIGMA_PARAMETERS for b in filters.NAMES)
    assert parameter_family("bytetrack_kf") == ACCEPTS["bytetrack_kf"] == tuple(STOCK)
    assert DEFAULT_TUNE["bytetrack_kf"] == ("std_weight_position", "std_weight_velocity")
    assert STOCK == {"std_weight_position": 1 / 20, "std_weight_velocity": 1 / 160, "std_aspect_measurement": 0.1}


BYTETRACK = ActionMap(tune=tuple(STOCK), K=2)


def test_bytetrack_weights_are_stock_times_decades_and_stock_when_untuned() -> None:
    p = BYTETRACK.to_params(np.array([[-1, -1, -1], [1, 1, 1], [0, 0.5, -0.5]]), NOMINAL)
    for name, stock in STOCK.items():
        np.testing.assert_allclose(p[name][:2], [stock * 10**-1.5, stock * 10**1.5])
    np.testing.assert_allclose([p[k][2] for k in STOCK], [1 / 20, 10**0.75 / 160, 0.1 * 10**-0.75])
    assert p["horizon"].tolist() == [24] * 3 and p["sigma_w"].tolist() == [10.0] * 3  # the others stay nominal
    untuned = FULL.to_params(np.zeros(4), [NOMINAL])
    assert {k: untuned[k].tolist() for k in STOCK} == {k: [v] for k, v in STOCK.items()}
    assert NOMINAL.as_params()["std_weight_velocity"].tolist() == [1 / 160]


@settings(max_examples=60, deadline=None)
@given(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), st.floats(-1.5, 1.5))
def test_bytetrack_params_actions_round_trip(lp: float, lv: float, lm: float) -> None:
    params = {k: stock * 10**e for (k, stock), e in zip(STOCK.items(), (lp, lv, lm), strict=False)}
    a = BYTETRACK.to_actions(params, NOMINAL)
    np.testing.assert_allclose(a[0], np.array([lp, lv, lm]) / 1.5, atol=1e-12)
    back = BYTETRACK.to_params(a.astype(np.float32), NOMINAL)  # policies emit float32
    for k, v in params.items():
        np.testing.assert_allclose(back[k][0], v, rtol=1e-5)
    with pytest.raises(ValueError, match="std_weight_position"):
        BYTETRACK.to_actions({**params, "std_weight_position": 1 / 20 * 10**1.6}, NOMINAL)


def test_mapping_endpoints() -> None:
    p = FULL.to_params(np.array([[-1, -1, -1, -1], [1, 1, 1, 1], [0, 0, 0, 0]]), NOMINAL)
    np.testing.assert_allclose(p["psi"], [0.0, 0.99, 0.495])
    np.testing.assert_array_equal(p["horizon"], [2, 400, round(2 * 200**0.5)])
    np.testing.assert_allclose(p["sigma_w"], [10 * 10**-1.5, 10 * 10**1.5, 10.0])
    np.testing.assert_allclose(p["sigma_v"], [2 * 10**-1.5, 2 * 10**1.5, 2.0])


def test_untuned_parameters_stay_nominal() -> None:
    amap = ActionMap(tune=("horizon",), K=2)
    p = amap.to_params(np.array([0.3]), NOMINAL)
    assert p["psi"][0] == 0.0 and p["sigma_w"][0] == 10.0 and p["sigma_v"][0] == 2.0


@settings(max_examples=60, deadline=None)
@given(st.floats(0, 0.99), st.integers(2, 400), st.floats(-1.5, 1.5), st.floats(-1.5, 1.5))
def test_params_actions_round_trip(psi: float, horizon: int, lw: float, lv: float) -> None:
    params = {"psi": psi, "horizon": horizon, "sigma_w": 10.0 * 10**lw, "sigma_v": 2.0 * 10**lv}
    a = FULL.to_actions(params, NOMINAL)
    back = FULL.to_params(a.astype(np.float32), NOMINAL)  # policies emit float32
    assert back["horizon"][0] == horizon
    np.testing.assert_allclose(back["psi"][0], psi, atol=1e-6)
    np.testing.assert_allclose(back["sigma_w"][0], params["sigma_w"], rtol=1e-5)


@pytest.mark.parametrize("bad", [[np.nan, 0, 0, 0], [0, np.inf, 0, 0], [0, 0, 1.01, 0], [0, 0, 0]])
def test_bad_actions_raise(bad: list[float]) -> None:
    with pytest.raises(ValueError, match="action"):
        FULL.to_params(np.array(bad), NOMINAL)


def test_unreachable_parameters_raise() -> None:
    with pytest.raises(ValueError, match="horizon"):
        FULL.to_actions({"psi": 0, "horizon": 1000, "sigma_w": 10, "sigma_v": 2}, NOMINAL)


def test_bad_tune_raises() -> None:
    with pytest.raises(ValueError, match="tune"):
        ActionMap(tune=("psi", "psi"), K=2)


def _track(rng: np.random.Generator, T: int = 400, sigma_v: float = 2.0, sigma_w: float = 30.0, tau: float = 0.05):
    from bboxtune.envs.data.simulate import Scenario, simulate

    track = simulate(Scenario(psi=0.0, sigma_w=sigma_w, sigma_xi=sigma_v, tau=tau, n_frames=T, ndim=4), rng)
    return track.truth, track.y


def test_features_finite_and_named() -> None:
    rng = np.random.default_rng(0)
    _, y = _track(rng)
    f = measurement_features(y, 0.05, 2.0, 30.0, y)
    assert f.shape == (len(FEATURE_NAMES),) and f.dtype == np.float32 and np.all(np.isfinite(f))


def test_batched_features_equal_one_track_at_a_time() -> None:
    rng = np.random.default_rng(1)
    ys = [_track(rng, T=300, sigma_v=sv, tau=tau)[1] for sv, tau in ((1.0, 0.05), (4.0, 0.033), (2.0, 0.1))]
    ys[1][[3, 50, 51, 200]] = np.nan  # missing frames: the NaN-aware path in one row only
    ys[2][:, 2:] = ys[2][0, 2:]  # constant size: degenerate size statistics
    pilots = [y + rng.normal(0, 0.5, y.shape) for y in ys]
    taus, sv, sw = [0.05, 0.033, 0.1], [1.0, 4.0, 2.0], [30.0, 10.0, 3.0]
    batch = measurement_features(np.stack(ys), taus, sv, sw, np.stack(pilots))
    assert batch.shape == (3, len(FEATURE_NAMES))
    for b in range(3):
        np.testing.assert_array_equal(batch[b], measurement_features(ys[b], taus[b], sv[b], sw[b], pilots[b]))
    sigmas = estimate_sigmas(np.stack(ys), np.array(taus))
    for b in range(3):
        assert (sigmas[0][b], sigmas[1][b]) == estimate_sigmas(ys[b], taus[b])


def test_features_finite_on_degenerate_input() -> None:
    y = np.full((10, 4), 5.0)
    y[3] = np.nan
    f = measurement_features(y, 0.05, 1.0, 1.0, y)
    assert np.all(np.isfinite(f))
    assert f[FEATURE_NAMES.index("frac_missing")] == pytest.approx(0.1)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_features_of_a_few_frames_are_finite_without_warnings(n: int) -> None:
    """1–3 frames (a re-tuning env's last window can be that short): no difference series or an empty one — the
    features are the floors, computed without a mean of an empty slice."""
    import warnings

    y = np.column_stack([np.arange(n) + 50.0, np.arange(n) * 2.0 + 40.0, np.full(n, 20.0), np.full(n, 30.0)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f = measurement_features(y, 0.05, 1.0, 1.0, y + 0.5)
    assert np.all(np.isfinite(f))
    assert f[FEATURE_NAMES.index("log_n_frames")] == pytest.approx(np.log(n))


def test_sigma_estimates_recover_white_noise_statistics() -> None:
    rng = np.random.default_rng(3)
    _, y = _track(rng, T=20000, sigma_v=2.0, sigma_w=30.0)
    sv, sw = estimate_sigmas(y, 0.05)
    assert sv == pytest.approx(2.0, rel=0.05)
    assert sw == pytest.approx(30.0, rel=0.25)


def test_nominal_of_the_rule_and_as_params() -> None:
    from bboxtune.filters.horizon import rule_horizon

    nominal = Nominal.of_rule(sigma_v=4.0, sigma_w=50.0, tau=0.05, psi=0.6, horizon_max=400)
    assert nominal.horizon == int(rule_horizon(4.0, 50.0, 0.05, 2, max_horizon=400)) and nominal.psi == 0.6
    assert Nominal.of_rule(4.0, 1e-6, 0.05, 0.0, horizon_max=30).horizon == 30  # N_opt capped at N_max
    params = nominal.as_params()
    assert sorted(params) == sorted(TUNABLE) and all(v.shape == (1,) for v in params.values())
    np.testing.assert_array_equal(ActionMap(tune=TUNABLE, K=2).to_params(
        ActionMap(tune=TUNABLE, K=2).to_actions(params, nominal), nominal)["horizon"], params["horizon"])


def test_stacked_nominals_are_the_rows_of_as_params() -> None:
    nominals = [NOMINAL, Nominal.of_rule(4.0, 50.0, 0.05, 0.6, horizon_max=400), Nominal(1.5, 3.0, 0.25, 7)]
    stacked = Nominal.stacked(nominals)
    assert sorted(stacked) == sorted(TUNABLE)
    for k in TUNABLE:
        rows = np.concatenate([n.as_params()[k] for n in nominals])
        np.testing.assert_array_equal(stacked[k], rows)
        assert stacked[k].dtype == rows.dtype
