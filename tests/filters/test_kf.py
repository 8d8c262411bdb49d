"""KF back end: equality with filterpy's KalmanFilter, batching, missing data, start-up, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters import kalman_core
from bboxtune.filters.model import StateSpaceModel

TAU = 0.05


def simulate(rng: np.random.Generator, T: int, M: int, sigma_w: float, sigma_v: float,
             B: int | None = None) -> np.ndarray:
    """Constant-velocity tracks (white acceleration) plus white noise: (T, M) or (B, T, M)."""
    shape = (T, M) if B is None else (B, T, M)
    acc = rng.normal(size=shape) * sigma_w
    vel = 20.0 + np.cumsum(acc * TAU, axis=-2)
    pos = 100.0 + np.cumsum(vel * TAU, axis=-2)
    return pos + rng.normal(size=shape) * sigma_v


def filterpy_run(model: StateSpaceModel, y: np.ndarray, sigma_w: float, sigma_v: float, x0: np.ndarray,
                 P0: np.ndarray) -> np.ndarray:
    """filterpy KalmanFilter on the full model: predict(); update(y_n) (None for a NaN row). (T, K)."""
    kf = KalmanFilter(dim_x=model.K, dim_z=model.M)
    kf.F, kf.H = model.F.copy(), model.H.copy()
    kf.Q = sigma_w**2 * model.B @ model.B.T
    kf.R = sigma_v**2 * np.eye(model.M)
    kf.x, kf.P = x0.astype(float).copy(), P0.astype(float).copy()
    out = []
    for row in y:
        kf.predict()
        kf.update(None if np.isnan(row).any() else row)
        out.append(kf.x.copy())
    return np.array(out)


def assert_rel(a: np.ndarray, b: np.ndarray, tol: float) -> None:
    """max |a − b| <= tol · max |b| (states reach 1e3–1e4, so absolute tolerances would be meaningless)."""
    assert np.max(np.abs(a - b)) <= tol * np.max(np.abs(b)), np.max(np.abs(a - b))


@pytest.mark.parametrize("M", [1, 4])
def test_equals_filterpy(M: int) -> None:
    rng = np.random.default_rng(M)
    model = filters.constant_velocity(TAU, ndim=M)
    y = simulate(rng, 1500, M, 50.0, 4.0)
    x0 = np.r_[np.full(M, 100.0), np.full(M, 20.0)]
    P0 = np.diag(np.r_[np.full(M, 10.0), np.full(M, 100.0)])
    P0[0, M] = P0[M, 0] = 5.0  # position–velocity correlation of coordinate 0
    ours = filters.make("kf", model, sigma_w=50.0, sigma_v=4.0, x0=x0, P0=P0).run(y)
    assert_rel(ours, filterpy_run(model, y, 50.0, 4.0, x0, P0), 1e-12)


def test_missing_frames_are_predict_only_like_filterpy() -> None:
    rng = np.random.default_rng(3)
    model = filters.constant_velocity(TAU, ndim=4)
    y = simulate(rng, 400, 4, 30.0, 3.0)
    y[[0, 7, 8, 9, 200]] = np.nan
    x0, P0 = np.zeros(8), np.diag(np.r_[np.full(4, 100.0), np.full(4, 1e4)])
    ours = filters.make("kf", model, sigma_w=30.0, sigma_v=3.0, x0=x0, P0=P0).run(y)
    assert_rel(ours, filterpy_run(model, y, 30.0, 3.0, x0, P0), 1e-12)
    assert np.all(np.isfinite(ours))


def test_batched_equals_one_track_at_a_time_and_per_track_arrays() -> None:
    rng = np.random.default_rng(4)
    model = filters.constant_velocity(TAU, ndim=2)
    y = simulate(rng, 300, 2, 10.0, 2.0, B=5)
    y[1, 50:60, 0] = np.nan  # a gap in one coordinate of one track: its own gain sequence
    y[3, :4] = np.nan  # late start
    sigma_w = np.array([1.0, 10.0, 10.0, 300.0, 0.1])
    sigma_v = np.array([2.0, 2.0, 0.5, 9.0, 2.0])
    batched = filters.make("kf", model, sigma_w=sigma_w, sigma_v=sigma_v).run(y)
    for b in range(5):
        single = filters.make("kf", model, sigma_w=sigma_w[b], sigma_v=sigma_v[b]).run(y[b])
        np.testing.assert_allclose(batched[b], single, rtol=1e-12, atol=1e-9)
    same = filters.make("kf", model, sigma_w=10.0, sigma_v=2.0).run(y)
    for b in range(5):
        np.testing.assert_allclose(same[b], filters.make("kf", model, sigma_w=10.0, sigma_v=2.0).run(y[b]),
                                   rtol=1e-12, atol=1e-9)


def test_many_tunings_frame_by_frame_equal_each_alone_in_blocks() -> None:
    rng = np.random.default_rng(6)
    model = filters.constant_velocity(TAU)
    y = simulate(rng, 200, 1, 10.0, 2.0, B=12)
    y[2, 30:35] = np.nan
    sigma_w = np.geomspace(0.1, 500.0, 12)  # more rows than kalman_core.BLOCK_ROWS: the frame-by-frame path
    assert len(sigma_w) > kalman_core.BLOCK_ROWS
    batched = filters.make("kf", model, sigma_w=sigma_w, sigma_v=2.0).run(y)
    for b in range(12):
        np.testing.assert_allclose(batched[b], filters.make("kf", model, sigma_w=sigma_w[b], sigma_v=2.0).run(y[b]),
                                   rtol=1e-12, atol=1e-9)


def test_start_from_first_measurement() -> None:
    model = filters.constant_velocity(TAU)
    y = np.array([np.nan, np.nan, 10.0, 10.5, 11.0, np.nan, 12.0])[:, None]
    out = filters.make("kf", model, sigma_w=5.0, sigma_v=0.5).run(y)
    assert np.all(np.isnan(out[:2]))  # nothing measured yet
    np.testing.assert_array_equal(out[2], [10.0, 0.0])  # x = [y, 0] at the first finite frame
    # diffuse velocity prior: the second measurement fixes the velocity at the two-point slope
    np.testing.assert_allclose(out[3, 1], (10.5 - 10.0) / TAU, rtol=1e-4)
    assert np.all(np.isfinite(out[2:]))
    # P0 without x0 is the covariance of that initial state: a confident zero velocity stays near zero
    sure = filters.make("kf", model, sigma_w=5.0, sigma_v=0.5, P0=np.diag([0.25, 1e-6])).run(y)
    assert abs(sure[3, 1]) < 1e-3 * abs(out[3, 1])


def test_all_missing_track_is_nan_and_does_not_disturb_others() -> None:
    rng = np.random.default_rng(5)
    model = filters.constant_velocity(TAU)
    y = simulate(rng, 50, 1, 10.0, 1.0, B=2)
    alone = filters.make("kf", model).run(y[0])
    y[1] = np.nan
    out = filters.make("kf", model).run(y)
    assert np.all(np.isnan(out[1]))
    np.testing.assert_array_equal(out[0], alone)


def test_steady_state_gain_matches_riccati() -> None:
    """After convergence the filter applies the DARE gain: compare a late impulse response."""
    from scipy.linalg import solve_discrete_are

    axis = filters.constant_velocity(TAU).axis()
    sigma_w, sigma_v = 50.0, 4.0
    Q = sigma_w**2 * axis.B @ axis.B.T
    P_prior = solve_discrete_are(axis.F.T, axis.H.T, Q, np.array([[sigma_v**2]]))
    K = P_prior @ axis.H.T / (axis.H @ P_prior @ axis.H.T + sigma_v**2)
    y = np.zeros((600, 1))
    y[500] = 1.0
    out = filters.make("kf", filters.constant_velocity(TAU), sigma_w=sigma_w, sigma_v=sigma_v,
                       x0=np.zeros(2), P0=np.eye(2)).run(y)
    np.testing.assert_allclose(out[500], K[:, 0], rtol=1e-10)


@settings(max_examples=25, deadline=None)
@given(
    sigma_w=st.floats(1e-6, 1e6),
    sigma_v=st.floats(1e-6, 1e6),
    scale=st.floats(1e-3, 1e4),
    seed=st.integers(0, 2**16),
)
def test_finite_input_gives_finite_output(sigma_w: float, sigma_v: float, scale: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    y = rng.normal(size=(2, 40, 4)) * scale
    y[0, 5] = np.nan
    out = filters.make("kf", filters.constant_velocity(TAU, ndim=4), sigma_w=sigma_w, sigma_v=sigma_v).run(y)
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"sigma_w": 0.0}, "sigma_w"),
        ({"sigma_v": -1.0}, "sigma_v"),
        ({"sigma_v": np.inf}, "sigma_v"),
        ({"sigma_w": np.array([1.0, np.nan])}, "sigma_w"),
        ({"x0": np.zeros(3)}, "x0"),
        ({"x0": np.array([0.0, np.nan])}, "x0"),
        ({"P0": np.eye(3)}, "P0"),
        ({"P0": np.array([[1.0, 0.5], [0.0, 1.0]])}, "symmetric"),
        ({"P0": np.array([[1.0, 2.0], [2.0, 1.0]])}, "eigenvalue"),
        ({"bogus": 1.0}, "bogus"),
    ],
)
def test_bad_parameters(params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        filters.make("kf", filters.constant_velocity(TAU), **params)


def test_bad_measurements_and_batch_mismatch() -> None:
    f = filters.make("kf", filters.constant_velocity(TAU, ndim=2), sigma_w=np.ones(3))
    with pytest.raises(ValueError, match="rank"):
        f.run(np.zeros(10))
    with pytest.raises(ValueError, match="M=2"):
        f.run(np.zeros((3, 10, 4)))
    with pytest.raises(ValueError, match="sigma_w"):
        f.run(np.zeros((2, 10, 2)))
    with pytest.raises(ValueError, match="couples"):
        P0 = np.eye(4)
        P0[0, 1] = P0[1, 0] = 0.1  # x–y coupling
        filters.make("kf", filters.constant_velocity(TAU, ndim=2), P0=P0)
