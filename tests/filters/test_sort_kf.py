"""bboxtune.filters.sort_kf: SORT's box Kalman filter, batched, against filterpy's ``KalmanFilter(dim_x=7, dim_z=4)`` configured
as SORT's ``KalmanBoxTracker`` configures it ([Bewley-SORT]; SORT itself runs on filterpy)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from bboxtune import filters
from bboxtune.filters.base import Carry

TAU = 1 / 25


def reference(boxes: np.ndarray) -> np.ndarray:
    """One track (T, 4) (cx, cy, w, h), NaN rows missing → states (T, 8): boxes, then their rates per second."""
    out = np.full((len(boxes), 8), np.nan)
    kf = None
    for t, (cx, cy, w, h) in enumerate(boxes):
        z = np.array([[cx], [cy], [w * h], [w / h]])
        if kf is None:
            if np.isnan(h):
                continue
            kf = KalmanFilter(dim_x=7, dim_z=4)
            kf.F = np.eye(7)
            kf.F[0, 4] = kf.F[1, 5] = kf.F[2, 6] = 1.0  # constant velocity of u, v, s; r constant
            kf.H = np.eye(4, 7)
            kf.R[2:, 2:] *= 10.0
            kf.P[4:, 4:] *= 1000.0  # the unobserved initial rates: very uncertain
            kf.P *= 10.0
            kf.Q[-1, -1] *= 0.01
            kf.Q[4:, 4:] *= 0.01
            kf.x[:4] = z
        else:
            if kf.x[6, 0] + kf.x[2, 0] <= 0:  # the area must not shrink through zero
                kf.x[6] *= 0.0
            kf.predict()
            if not np.isnan(h):
                kf.update(z)
        u, v, s, r, du, dv, ds = kf.x[:, 0]
        width = np.sqrt(s * r)
        height = s / width
        out[t] = [u, v, width, height, du / TAU, dv / TAU, width * ds / (2 * s) / TAU, height * ds / (2 * s) / TAU]
    return out


def boxes(n_tracks: int, T: int, seed: int, missing: float = 0.2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = np.empty((n_tracks, T, 4))
    y[..., :2] = 300 + np.cumsum(rng.normal(0, 3, (n_tracks, T, 2)), axis=1)
    y[..., 2:] = rng.uniform(20, 120, (n_tracks, 1, 2)) * np.exp(np.cumsum(rng.normal(0, 0.03, (n_tracks, T, 2)), 1))
    y[rng.random((n_tracks, T)) < missing] = np.nan
    return y


def assert_matches_reference(y: np.ndarray, states: np.ndarray) -> None:
    for b in range(len(y)):
        ref = reference(y[b])
        np.testing.assert_array_equal(np.isnan(states[b]), np.isnan(ref))
        scale = np.nanmax(np.abs(ref), axis=0, initial=1.0)  # rates near 0: relative to the column's scale
        assert np.nanmax(np.abs(states[b] - ref) / scale, initial=0.0) <= 1e-9


def shrinking(T: int = 40) -> np.ndarray:
    """A box shrinking fast, then lost: unguarded, the predicted area would cross zero."""
    y = np.full((T, 4), np.nan)
    size = 100.0 * 0.7 ** np.arange(10)
    y[:10] = np.stack([np.full(10, 50.0), np.full(10, 60.0), size, size * 1.5], axis=1)
    return y


def test_matches_filterpy_configured_as_sort_on_random_tracks_with_missing_frames() -> None:
    y = boxes(10, 80, 0)
    y[1, :10] = np.nan  # starts late
    y[2, 30:60] = np.nan  # a long gap
    y[3] = np.nan  # never detected
    y[4] = shrinking(80)  # the area-rate guard fires
    states = filters.make("sort_kf", filters.constant_velocity(TAU, ndim=4)).run(y)
    assert states.shape == (10, 80, 8)
    assert_matches_reference(y, states)
    assert np.all(states[4, 10:, 2] > 0)  # the guard kept the area positive


def test_the_guard_matters() -> None:
    y = shrinking()
    kf = filters.make("sort_kf", filters.constant_velocity(TAU, ndim=4))
    np.testing.assert_allclose(kf.run(y), reference(y), rtol=1e-9, atol=1e-9)
    est = kf.run(y)
    assert np.all(np.diff(est[12:, 2]) == 0)  # area rate 0 once s + s' <= 0: the box holds its size


def test_single_track_empty_batches_first_frame_missing() -> None:
    flt = filters.make("sort_kf", filters.constant_velocity(TAU, ndim=4))
    y = boxes(1, 30, 1)[0]
    y[0] = np.nan
    states = flt.run(y)
    assert states.shape == (30, 8) and np.isnan(states[0]).all()
    np.testing.assert_allclose(states, reference(y), rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(flt.positions(y), states[:, :4])
    assert flt.run(np.empty((0, 5, 4))).shape == (0, 5, 8)
    assert flt.run(np.empty((2, 0, 4))).shape == (2, 0, 8)
    assert np.isnan(flt.run(np.full((2, 6, 4), np.nan))).all()


def test_no_parameters_and_input_errors() -> None:
    cls = filters.filter_class("sort_kf")
    assert cls.DEFAULTS == {} and "sort_kf" in filters.PEER_NAMES and "sort_kf" not in filters.NAMES
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['sigma_v'\]; allowed: \[\]"):
        filters.make("sort_kf", filters.constant_velocity(TAU, ndim=4), sigma_v=1.0)
    with pytest.raises(ValueError, match="M=1"):
        filters.make("sort_kf", filters.constant_velocity(TAU))
    y = boxes(2, 5, 2, missing=0.0)
    y[1, 4, 2] = -3.0
    with pytest.raises(ValueError, match=r"y\[1, 4\] has w = -3.0; allowed: box sizes w, h >= 1e-30"):
        filters.make("sort_kf", filters.constant_velocity(TAU, ndim=4)).run(y)


def test_run_from_split_equals_the_whole_run_and_the_carry_holds_sort_s_state() -> None:
    y = boxes(5, 70, 3)
    y[0, :45] = np.nan  # starts after the split
    y[1] = shrinking(70)
    flt = filters.make("sort_kf", filters.constant_velocity(TAU, ndim=4))
    whole = flt.run(y)
    first, carry = flt.run_from(y[:, :30])
    rest, _ = flt.run_from(y[:, 30:], carry)
    np.testing.assert_allclose(np.concatenate([first, rest], axis=1), whole, rtol=1e-12, atol=1e-9)
    assert np.isnan(carry.x[0]).all() and not carry.measured[0].any() and carry.measured[1:].all()
    assert np.all(carry.x[1:, 7] == 0) and np.all(carry.P[1:, 7] == 0)  # r has no rate
    x = carry.x.copy()
    x[1, 7] = 0.5
    with pytest.raises(ValueError, match=r"no rate for coordinate\(s\) \[3\]"):
        flt.run_from(y[:, 30:], Carry(x=x, P=carry.P, y_last=carry.y_last, measured=carry.measured))


def test_batch_runners_without_parameters() -> None:
    ys, taus = [boxes(1, 50, 4)[0], boxes(1, 30, 5)[0]], [1 / 30, 0.1]
    est = filters.track_positions("sort_kf", ys, taus, {})
    for i in range(2):
        np.testing.assert_allclose(est[i], reference(ys[i])[:, :4], rtol=1e-9)
        np.testing.assert_array_equal(filters.candidate_positions("sort_kf", ys[i], taus[i], {})[0], est[i])
