"""The features' compiled kernels (``bboxtune.envs.episodes.features_kernels``) against their numpy references on random
tracks with missing frames (NaN rows and gaps), to ≤ 1e-9 relative; the box scale bit for bit (it sets the nominal σ of
some sources' episodes)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune.envs.episodes import features, features_kernels
from bboxtune.filters import jit
from tests.kernel_modes import both


@st.composite
def tracks(draw: st.DrawFn, min_frames: int = 1) -> np.ndarray:
    """Box tracks (B, T, 4): random walks around a box, with NaN rows, whole gaps, single NaN values, non-positive
    sizes (now and then) and all-missing tracks."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    B, T = draw(st.integers(1, 4)), draw(st.integers(min_frames, 120))
    y = np.cumsum(rng.normal(0, draw(st.floats(0.01, 20.0)), (B, T, 4)), axis=1) + [320.0, 240.0, 60.0, 40.0]
    y[rng.random((B, T)) < draw(st.sampled_from([0.0, 0.0, 0.1, 0.5, 0.95]))] = np.nan
    for b, start in enumerate(rng.integers(0, T, B)):
        if draw(st.booleans()):
            y[b, start:start + draw(st.integers(1, 40))] = np.nan  # a gap
    if draw(st.booleans()):
        y[rng.integers(0, B), rng.integers(0, T), rng.integers(0, 4)] = np.nan  # one coordinate missing
    if draw(st.booleans()):
        y[rng.integers(0, B), :, 2] *= -1  # no positive area
    if draw(st.booleans()):
        y[rng.integers(0, B)] = np.nan  # nothing measured
    return y


def _close(got: np.ndarray, want: np.ndarray, scale: np.ndarray) -> None:
    """≤ 1e-9 relative, with an absolute floor 1e-9 × ``scale`` (the size of the sums, where a covariance cancels)."""
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * float(np.max(scale, initial=0.0)) + 1e-300)


@settings(max_examples=60, deadline=None)
@given(tracks(), st.sampled_from([(0, 1), (1, 1), (2, 1), (2, 2), (2, 4), (2, 16)]), st.integers(0, 3),
       st.sampled_from([(0, 4), (0, 2), (2, 4)]))
def test_autocovariances_equal_numpy(y: np.ndarray, order_stride: tuple[int, int], lags: int, series: tuple[int, int]) -> None:
    Y = np.ascontiguousarray(np.swapaxes(y, 1, 2))
    order, stride = order_stride
    got = features_kernels.autocovariances(Y, series[0], series[1], order, stride, lags)
    want = features.autocovariance(features.differences(Y[:, series[0]:series[1]], order, stride), lags)
    assert got.shape == want.shape
    _close(got, want, want[:, :1])


@settings(max_examples=60, deadline=None)
@given(tracks())
def test_scale_equals_numpy_bit_for_bit(y: np.ndarray) -> None:
    area = y[..., 2] * y[..., 3]
    np.testing.assert_array_equal(features_kernels.median_scale(np.ascontiguousarray(area)), features.scale_numpy(area))
    kernel, reference = both(lambda: features.box_scale(y[0]))
    assert kernel == reference and isinstance(kernel, float)


@settings(max_examples=40, deadline=None)
@given(tracks(min_frames=3))
def test_statistics_equal_numpy(y: np.ndarray) -> None:
    """Every autocovariance to 1e-9 of its group's variance; the box scale and the fraction missing exactly."""
    k = features_kernels
    Y = np.ascontiguousarray(np.swapaxes(y, 1, 2))
    resid = Y - np.random.default_rng(0).normal(300, 50, Y.shape)
    got, want = k.measurement_statistics(Y, resid), features.statistics_numpy(Y, resid)
    for group in (slice(k.D1_POS, k.D1_POS + 4), slice(k.D2_POS, k.D2_POS + 4), slice(k.D1_SIZE, k.D1_SIZE + 1),
                  slice(k.D2_SIZE, k.D2_SIZE + 1), slice(k.RESID, k.RESID + 2)):
        _close(got[:, group], want[:, group], want[:, group.start])
    for i in range(len(k.STRIDES)):
        _close(got[:, k.STRIDED + i], want[:, k.STRIDED + i], want[:, k.STRIDED + i])
    np.testing.assert_array_equal(got[:, k.SCALE:], want[:, k.SCALE:])


@settings(max_examples=40, deadline=None)
@given(tracks(min_frames=3), st.floats(0.01, 1.0))
def test_features_equal_numpy(y: np.ndarray, tau: float) -> None:
    """σ̂ to 1e-9; the observation (float32) to float32 rounding; the window features of the first track."""
    B = len(y)
    rule = y + np.random.default_rng(0).normal(0, 1, y.shape)
    taus = tau * np.linspace(1.0, 2.0, B)
    (sv_k, sw_k), (sv_n, sw_n) = both(lambda: features.estimate_sigmas(y, taus))
    _close(sv_k, sv_n, sv_n)
    _close(sw_k, sw_n, sw_n)
    (sv_k, sw_k), (sv_n, sw_n) = both(lambda: features.estimate_sigmas(y[0, :, :2], tau))  # one track, positions only
    np.testing.assert_allclose([sv_k, sw_k], [sv_n, sw_n], rtol=1e-9)
    for fn in (lambda: features.measurement_features(y, taus, 3.0, 10.0, rule),
               lambda: features.window_features(y[0], rule[0], y[0] + 0.5)):
        kernel, reference = both(fn)
        assert np.isfinite(kernel).all()
        np.testing.assert_allclose(kernel, reference, rtol=1e-5, atol=1e-5)


@settings(max_examples=40, deadline=None)
@given(tracks(min_frames=3), st.floats(0.01, 1.0), st.floats(0.1, 10.0))
def test_observation_equals_numpy(y: np.ndarray, tau: float, nominal: float) -> None:
    """The observation from given statistics and σ̂ to 1e-9 relative (absolute for values near 0: correlations)."""
    B, T = y.shape[:2]
    Y = np.ascontiguousarray(np.swapaxes(y, 1, 2))
    stats = features.statistics_numpy(Y, Y - 1.0)
    taus = tau * np.linspace(1.0, 2.0, B)
    sv, sw = features.sigmas_numpy(stats[:, 4], stats[:, 5], stats[:, 12:17], taus, stats[:, 17], T)
    got, valid = features_kernels.observation(stats, taus, sv, sw, np.full(B, nominal), np.full(B, 2 * nominal), T,
                                              (1e-30, 1e30), (1e-6, 1e6))
    assert valid
    want = features.observation_numpy(stats, taus, sv, sw, nominal, 2 * nominal, T)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(("nominal", "error"), [(-1.0, ValueError), (np.nan, ValueError), ("1", TypeError), (1e31, ValueError)])
def test_invalid_nominal_raises_in_both_modes(nominal: object, error: type[Exception]) -> None:
    y = np.cumsum(np.random.default_rng(0).normal(size=(50, 4)), axis=0) + [320.0, 240.0, 60.0, 40.0]
    for enabled in (True, False):
        with pytest.MonkeyPatch.context() as mp, pytest.raises(error, match="sigma_v"):
            mp.setattr(jit, "ENABLED", enabled)
            features.measurement_features(y, 0.04, nominal, 10.0, y)


@settings(max_examples=40, deadline=None)
@given(tracks(min_frames=3), st.floats(0.01, 1.0), st.floats(0.1, 10.0))
def test_the_one_call_observation_is_the_three_kernels_bit_for_bit(y: np.ndarray, tau: float, nominal: float) -> None:
    """``track_observations`` (what ``measurement_features`` calls) = statistics, σ̂ and observation kernels in turn."""
    k = features_kernels
    B, T = y.shape[:2]
    rule = y + np.random.default_rng(1).normal(0, 1, y.shape)
    taus, nominal_v, nominal_w = tau * np.linspace(1.0, 2.0, B), np.full(B, nominal), np.full(B, 3 * nominal)
    got, got_valid = k.track_observations(y, rule, taus, nominal_v, nominal_w, (1e-30, 1e30), (1e-6, 1e6))
    Y = np.ascontiguousarray(np.swapaxes(y, 1, 2))
    stats = k.measurement_statistics(Y, np.ascontiguousarray(Y - np.swapaxes(rule, 1, 2)))
    c0, c1, strided, scale = (np.ascontiguousarray(stats[:, c]) for c in (k.D2_POS, k.D2_POS + 1,
                                                                           slice(k.STRIDED, k.SCALE), k.SCALE))
    sv, sw = k.sigmas(c0, c1, strided, taus, scale, T)
    want, valid = k.observation(stats, taus, sv, sw, nominal_v, nominal_w, T, (1e-30, 1e30), (1e-6, 1e6))
    assert got_valid == valid
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(features.measurement_features(y[0], tau, nominal, 3 * nominal, rule[0]),
                                  want[0].astype(np.float32))


@settings(max_examples=60, deadline=None)
@given(tracks(min_frames=2))
def test_position_msd_equals_numpy(y: np.ndarray) -> None:
    """The mean squared displacement to 1e-9 relative (NaN where fewer than 4 pairs are measured, in both); inf values
    count as missing in both."""
    y = y.copy()
    y[0, 0, 0] = np.inf if y.shape[1] > 2 else y[0, 0, 0]
    got = features_kernels.position_msd(np.ascontiguousarray(y), features.msd_lag(y.shape[1]))
    want = features.position_msd_numpy(y)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got, want, rtol=1e-9)
    kernel, reference = both(lambda: features.msd_feature(y, np.log(features.box_scale(y))))
    assert np.isfinite(kernel).all()
    np.testing.assert_allclose(kernel, reference, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(("n_frames", "lag"), [(2, 1), (3, 1), (100, 50), (128, 64), (5000, 64)])
def test_msd_lag_is_at_most_half_the_track(n_frames: int, lag: int) -> None:
    assert features.msd_lag(n_frames) == lag


def test_msd_feature_tells_slow_coloured_noise_from_motion() -> None:
    """Two tracks with the same short-lag noise level: CMN with ψ = 0.9 around a box at rest (bounded MSD, 2σ²/(1 − ψ²)
    per coordinate at long lags) and a box moving at 1 px/frame with white noise (MSD ≈ 64² px²): the feature is
    what the formula gives, and the moving track's is the larger by ~log(64² / 2σ_v²)."""
    rng = np.random.default_rng(0)
    T, scale = 2000, 50.0
    xi = rng.normal(0, 1.0, (T, 2))
    cmn = np.zeros((T, 2))
    for t in range(1, T):
        cmn[t] = 0.9 * cmn[t - 1] + xi[t]
    box = np.array([320.0, 240.0, scale, scale])
    resting = np.tile(box, (T, 1))
    resting[:, :2] += cmn
    moving = np.tile(box, (T, 1)) + rng.normal(0, 1.0, (T, 4)) * [1, 1, 0, 0]
    moving[:, 0] += np.arange(T)
    y = np.stack([resting, moving])
    got = features.msd_feature(y, np.log(features.box_scale(y)))
    stationary = 2 * 1.0 / (1 - 0.9**2)  # E[(v_{t+k} − v_t)²] per coordinate for k ≫ 1/(1 − ψ), averaged over cx, cy
    assert got[0] == pytest.approx(np.log(stationary / scale**2), abs=0.15)
    assert got[1] == pytest.approx(np.log((64.0**2 / 2 + 2.0) / scale**2), abs=0.05)


def test_measurement_features_with_msd_append_one_entry() -> None:
    """``msd=True``: the 20 base entries unchanged and the feature last, for a batch and for one track alike; a track
    with fewer than 4 measured pairs gets the floor."""
    rng = np.random.default_rng(3)
    y = np.cumsum(rng.normal(0, 2, (3, 300, 4)), axis=1) + [320.0, 240.0, 60.0, 40.0]
    y[1, 50:120] = np.nan
    rule = y + rng.normal(0, 1, y.shape)
    base = features.measurement_features(y, 0.05, 3.0, 10.0, rule)
    with_msd = features.measurement_features(y, 0.05, 3.0, 10.0, rule, msd=True)
    assert with_msd.shape == (3, 21) and with_msd.dtype == np.float32
    np.testing.assert_array_equal(with_msd[:, :20], base)
    np.testing.assert_array_equal(features.measurement_features(y[1], 0.05, 3.0, 10.0, rule[1], msd=True), with_msd[1])
    assert features.feature_names("msd")[-1] == features.MSD_FEATURE and len(features.feature_names("msd")) == 21
    sparse = np.full((1, 300, 4), np.nan)
    sparse[0, [0, 64, 128]] = [320.0, 240.0, 60.0, 40.0]  # two pairs 64 frames apart
    assert features.measurement_features(sparse, 0.05, 3.0, 10.0, sparse, msd=True)[0, -1] == np.float32(np.log(1e-12))


@pytest.mark.parametrize("lags", [-1, 4])
def test_autocovariances_refuse_lags_beyond_three(lags: int) -> None:
    """The kernel sums lags 0 to 3 side by side: more are refused, not left out."""
    with pytest.raises(ValueError, match="lags: allowed 0 to 3"):
        features_kernels.autocovariances(np.zeros((1, 4, 20)), 0, 4, 1, 1, lags)
