"""UKF back end: equals the KF on the linear model, agrees with filterpy's UnscentedKalmanFilter, the
camera-motion model ([Raj-UKF] eq. 17) against a 3-state linear KF, batching, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from tests.filters.test_kf import assert_rel, simulate

TAU = 0.05
X0, P0 = np.array([100.0, 20.0]), np.diag([10.0, 100.0])


@pytest.mark.parametrize("M", [1, 4])
def test_equals_kf_at_alpha_one(M: int) -> None:
    rng = np.random.default_rng(M)
    model = filters.constant_velocity(TAU, ndim=M)
    y = simulate(rng, 1000, M, 50.0, 4.0, B=2)
    y[0, 10:13] = np.nan
    kf = filters.make("kf", model, sigma_w=50.0, sigma_v=4.0).run(y)
    ukf = filters.make("ukf", model, sigma_w=50.0, sigma_v=4.0).run(y)
    assert_rel(ukf, kf, 1e-8)  # measured ~1e-14


@pytest.mark.parametrize("alpha", [1e-4, 1e-3, 1.0, 1e4])
def test_any_alpha_equals_kf_to_rounding(alpha: float) -> None:
    """The sigma points are drawn around 0 and only carry covariances (module docstring): α = 1e-3 ([Raj-UKF]'s
    suggestion, W_0 = 1 − 1/α² ≈ −1e6) lost ~1e-9 relative to cancellation when they were drawn around x; now
    every α in range agrees with the KF to rounding (measured 1.2e-15 at 1e-3)."""
    rng = np.random.default_rng(2)
    model = filters.constant_velocity(TAU)
    y = simulate(rng, 1500, 1, 50.0, 4.0)
    kf = filters.make("kf", model, sigma_w=50.0, sigma_v=4.0, x0=X0, P0=P0).run(y)
    ukf = filters.make("ukf", model, sigma_w=50.0, sigma_v=4.0, x0=X0, P0=P0, alpha=alpha).run(y)
    assert np.max(np.abs(ukf - kf)) / np.max(np.abs(kf)) < 1e-12


@pytest.mark.parametrize(("alpha", "beta", "kappa"), [(1.0, 2.0, 0.0), (1.0, 2.0, 1.0), (0.5, 0.0, 0.5)])
def test_equals_filterpy_ukf(alpha: float, beta: float, kappa: float) -> None:
    rng = np.random.default_rng(5)
    axis = filters.constant_velocity(TAU).axis()
    y = simulate(rng, 500, 1, 30.0, 3.0)
    y[[3, 200]] = np.nan
    points = MerweScaledSigmaPoints(2, alpha=alpha, beta=beta, kappa=kappa)
    ref = UnscentedKalmanFilter(2, 1, TAU, hx=lambda x: x[:1], fx=lambda x, dt: axis.F @ x, points=points)
    ref.x, ref.P = X0.copy(), P0.copy()
    ref.Q, ref.R = 30.0**2 * axis.B @ axis.B.T, np.eye(1) * 9.0
    expected = []
    for row in y:
        ref.predict()
        ref.update(None if np.isnan(row[0]) else row)
        expected.append(ref.x.copy())
    ours = filters.make("ukf", filters.constant_velocity(TAU), sigma_w=30.0, sigma_v=3.0, x0=X0, P0=P0,
                        alpha=alpha, beta=beta, kappa=kappa).run(y)
    assert_rel(ours, np.array(expected), 1e-10)


def camera_track(rng: np.random.Generator, T: int, sigma_w: float, sigma_c: float) -> np.ndarray:
    """Per-coordinate states [q, r, c] of the module's camera model: (T, 3)."""
    F = np.array([[1.0, TAU, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    b_obj, b_cam = np.array([TAU**2 / 2, TAU, 0.0]), np.array([TAU**2 / 2, TAU, TAU])
    x, out = np.zeros(3), []
    for _ in range(T):
        x = F @ x + b_obj * rng.normal() * sigma_w + b_cam * rng.normal() * sigma_c
        out.append(x)
    return np.array(out)


CAMERA = {"sigma_w": 2.0, "sigma_v": 2.0, "sigma_c": 200.0, "sigma_u": 5.0}


def test_camera_model_equals_three_state_kalman_filter() -> None:
    rng = np.random.default_rng(11)
    s = camera_track(rng, 600, CAMERA["sigma_w"], CAMERA["sigma_c"])
    y = s[:, :1] + rng.normal(size=(600, 1)) * CAMERA["sigma_v"]
    u = s[:, 2:] + rng.normal(size=(600, 1)) * CAMERA["sigma_u"]
    u[0], y[50] = np.nan, np.nan  # no camera velocity at frame 0; a missed detection with u present
    ours = filters.make("ukf", filters.constant_velocity(TAU), camera_motion=True, x0=np.zeros(2),
                        P0=np.diag([1.0, 4.0]), **CAMERA).run(y, u=u)
    kf = KalmanFilter(dim_x=3, dim_z=2)
    kf.F = np.array([[1.0, TAU, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    b_obj, b_cam = np.array([TAU**2 / 2, TAU, 0.0]), np.array([TAU**2 / 2, TAU, TAU])
    kf.Q = CAMERA["sigma_w"] ** 2 * np.outer(b_obj, b_obj) + CAMERA["sigma_c"] ** 2 * np.outer(b_cam, b_cam)
    kf.x = np.zeros(3)
    kf.P = np.diag([1.0, 4.0, (1e3 * CAMERA["sigma_v"] / TAU) ** 2])  # documented camera-velocity prior
    H, R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), np.diag([CAMERA["sigma_v"] ** 2, CAMERA["sigma_u"] ** 2])
    expected = []
    for n in range(600):
        kf.predict()
        ok = ~np.isnan([y[n, 0], u[n, 0]])
        kf.update(np.array([y[n, 0], u[n, 0]])[ok], R=R[np.ix_(ok, ok)], H=H[ok])
        expected.append(kf.x[:2].copy())
    assert_rel(ours, np.array(expected), 1e-8)


def test_camera_velocity_input_lowers_error() -> None:
    """Smooth object, jittery camera: with u the position RMSE is about half that of the best uncompensated
    filter (a KF with acceleration variance σ_w² + σ_c², which is what camera_motion without u reduces to)."""
    rng = np.random.default_rng(12)
    model = filters.constant_velocity(TAU, ndim=2)
    s = np.stack([camera_track(rng, 600, CAMERA["sigma_w"], CAMERA["sigma_c"]) for _ in range(2)], axis=1)
    y = s[:, :, 0] + rng.normal(size=(600, 2)) * CAMERA["sigma_v"]
    u = s[:, :, 2] + rng.normal(size=(600, 2)) * CAMERA["sigma_u"]
    camera = filters.make("ukf", model, camera_motion=True, **CAMERA)
    with_u, without_u = camera.run(y, u=u), camera.run(y)
    best_plain = filters.make("kf", model, sigma_w=np.hypot(CAMERA["sigma_w"], CAMERA["sigma_c"]),
                              sigma_v=CAMERA["sigma_v"]).run(y)
    assert_rel(without_u, best_plain, 1e-8)

    def rmse(est: np.ndarray) -> float:
        return float(np.sqrt(np.mean((est[50:, :2] - s[50:, :, 0]) ** 2)))

    assert rmse(with_u) < 0.7 * rmse(best_plain)


def test_camera_states_only_on_centre_coordinates() -> None:
    rng = np.random.default_rng(13)
    model = filters.constant_velocity(TAU, ndim=4)
    y = simulate(rng, 200, 4, 10.0, 1.0)
    u = rng.normal(size=(200, 2)) * 50.0
    camera = filters.make("ukf", model, camera_motion=True, sigma_c=30.0).run(y, u=u)
    plain = filters.make("ukf", model).run(y)
    np.testing.assert_allclose(camera[:, [2, 3, 6, 7]], plain[:, [2, 3, 6, 7]], rtol=1e-12)  # w, h untouched
    assert not np.allclose(camera[:, :2], plain[:, :2])


def test_batched_equals_separate_runs() -> None:
    rng = np.random.default_rng(14)
    model = filters.constant_velocity(TAU, ndim=2)
    y = simulate(rng, 200, 2, 10.0, 2.0, B=3)
    y[1, :5] = np.nan
    u = rng.normal(size=(3, 200, 2))
    u[2, 10:20] = np.nan
    params = {"sigma_w": np.array([1.0, 10.0, 50.0]), "sigma_v": np.array([2.0, 1.0, 3.0]),
              "alpha": np.array([1.0, 0.5, 1e-2]), "kappa": np.array([0.0, 1.0, 0.0]),
              "sigma_c": np.array([5.0, 50.0, 1.0]), "sigma_u": np.array([1.0, 2.0, 3.0])}
    batched = filters.make("ukf", model, camera_motion=True, **params).run(y, u=u)
    for b in range(3):
        single = filters.make("ukf", model, camera_motion=True, **{k: v[b] for k, v in params.items()})
        np.testing.assert_allclose(batched[b], single.run(y[b], u=u[b]), rtol=1e-12, atol=1e-9)


def test_singular_prior_covariance_uses_eigen_square_root() -> None:
    y = simulate(np.random.default_rng(15), 100, 1, 10.0, 1.0)
    out = filters.make("ukf", filters.constant_velocity(TAU), x0=X0, P0=np.diag([1.0, 0.0])).run(y)
    kf = filters.make("kf", filters.constant_velocity(TAU), x0=X0, P0=np.diag([1.0, 0.0])).run(y)
    assert_rel(out, kf, 1e-8)


@settings(max_examples=20, deadline=None)
@given(sigma_w=st.floats(1e-6, 1e6), sigma_v=st.floats(1e-6, 1e6), seed=st.integers(0, 2**16))
def test_finite_input_gives_finite_output(sigma_w: float, sigma_v: float, seed: int) -> None:
    y = np.random.default_rng(seed).normal(size=(2, 30, 2)) * 100.0
    y[0, 4] = np.nan
    out = filters.make("ukf", filters.constant_velocity(TAU, ndim=2), sigma_w=sigma_w, sigma_v=sigma_v).run(y)
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize(
    ("params", "match"),
    [({"alpha": 0.0}, "alpha"), ({"beta": -1.0}, "beta"), ({"kappa": -2.0}, "kappa"),
     ({"sigma_c": -1.0}, "sigma_c"), ({"sigma_u": np.nan}, "sigma_u"), ({"camera_motion": 1}, "camera_motion")],
)
def test_bad_parameters(params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        filters.make("ukf", filters.constant_velocity(TAU), **params)


def test_bad_camera_input() -> None:
    model = filters.constant_velocity(TAU, ndim=4)
    y = np.zeros((10, 4))
    with pytest.raises(ValueError, match="no camera states"):
        filters.make("ukf", model).run(y, u=np.zeros((10, 2)))
    camera = filters.make("ukf", model, camera_motion=True)
    with pytest.raises(ValueError, match=r"u has shape \(10, 4\)"):
        camera.run(y, u=np.zeros((10, 4)))
    with pytest.raises(ValueError, match="inf"):
        camera.run(y, u=np.full((10, 2), np.inf))


def test_gains_stop_at_steady_state_on_long_tracks() -> None:
    """Without gaps the sigma-point gain recursion stops once the covariance repeats (a few hundred frames), so a
    track of 200,000 frames costs affine maps only — and equals the KF there."""
    from bboxtune.filters import kalman_core as kc
    from bboxtune.filters.ukf import sigma_gain_recursion

    axis = filters.constant_velocity(TAU).axis()
    kinds = kc.frame_kinds(np.ones((1, 200_000), bool), prior=False)
    coef, steady, _ = sigma_gain_recursion(kinds, np.array([[50.0, 4.0, 1.0, 2.0, 0.0]]),
                                           np.diag([16.0, 1e8])[:, :, None], axis)
    assert steady < 5_000 and np.all(coef[steady:] == coef[steady])
    y = 100.0 + np.cumsum(np.random.default_rng(5).normal(size=(200_000, 1)), axis=0)
    ukf = filters.make("ukf", filters.constant_velocity(TAU), sigma_w=50.0, sigma_v=4.0).run(y)
    kf = filters.make("kf", filters.constant_velocity(TAU), sigma_w=50.0, sigma_v=4.0).run(y)
    assert np.max(np.abs(ukf[:, 0] - kf[:, 0])) <= 1e-10 * np.max(np.abs(kf[:, 0]))
