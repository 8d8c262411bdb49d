"""The associative composition of per-frame Kalman elements (bboxtune.filters.window_scan) that OUFIR, OFIR and Kwon's FIR
use for windows with missing samples: the operator is associative, its rank-one single-frame forms equal the
general one, and the windowed estimates equal a KF run over every window separately (the previous method)."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.filters import jit
from bboxtune.filters import window_scan as ws
from bboxtune.filters.oufir import KalmanWindowFIR


def frame_model(n: int, seed: int, missing: float = 0.3) -> ws.FrameModel:
    rng = np.random.default_rng(seed)
    axis = filters.constant_velocity(1.0).axis()
    q = 10.0 ** rng.uniform(-4, 3, n)
    return ws.FrameModel(axis.F, axis.B[:, 0], q, rng.normal(0.0, 5.0, n), rng.random(n) > missing)


def elements(frames: ws.FrameModel, at: slice) -> ws.Elements:
    out = ws.Elements.empty(at.stop - at.start, frames.y.shape[:-1])
    frames.elements(at, out)
    return out


def test_composition_is_associative() -> None:
    frames = frame_model(3 * 50, seed=0)
    a, b, c = (elements(frames, slice(50 * i, 50 * (i + 1))) for i in range(3))
    left, right = ws.combine(ws.combine(a, b), c), ws.combine(a, ws.combine(b, c))
    np.testing.assert_allclose(left.array(), right.array(), rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(ws.Elements.of(left.array()).array(), left.array())


def test_single_frame_forms_equal_the_general_composition() -> None:
    frames = frame_model(2 * 40, seed=1)
    g = ws.combine(elements(frames, slice(0, 40)), elements(frames, slice(40, 80)))  # some compositions
    at = slice(40, 80)
    appended, prepended = ws.Elements.empty(40), ws.Elements.empty(40)
    frames.append(g, at, appended)
    frames.prepend(at, g, prepended)
    np.testing.assert_allclose(appended.array(), ws.combine(g, elements(frames, at)).array(), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(prepended.array(), ws.combine(elements(frames, at), g).array(), rtol=1e-10,
                               atol=1e-12)


def test_channels_sharing_missing_frames_compose_their_data_side_by_side() -> None:
    """Data rows with a leading channel axis (k channels, one structure): each channel's rows equal those of its
    own composition, and a composition without covariance differs only in the rows of C (NaN)."""
    rng = np.random.default_rng(4)
    axis = filters.constant_velocity(1.0).axis()
    n = 60
    q, valid = 10.0 ** rng.uniform(-4, 3, n), rng.random(n) > 0.3
    y = rng.normal(0.0, 5.0, (3, n))
    shared = ws.FrameModel(axis.F, axis.B[:, 0], q, y, valid)
    both = ws.combine(elements(shared, slice(0, 30)), elements(shared, slice(30, 60)))
    lean = ws.combine(elements(shared, slice(0, 30)), elements(shared, slice(30, 60)), covariance=False)
    for j in range(3):
        alone = ws.FrameModel(axis.F, axis.B[:, 0], q, y[j], valid)
        one = ws.combine(elements(alone, slice(0, 30)), elements(alone, slice(30, 60)))
        for row in range(14):
            got = both[row] if row in ws.STRUCTURE else both[row][j]
            np.testing.assert_allclose(got, one[row], rtol=1e-13, atol=1e-13)
            if row in (ws.C00, ws.C01, ws.C11):
                assert np.isnan(lean[row]).all()
            else:
                np.testing.assert_array_equal(lean[row], both[row])


def test_composed_window_equals_the_kalman_filter_over_it() -> None:
    """Frames lo … n composed, flat prior before lo: the KF (diffuse start) over the same frames."""
    rng = np.random.default_rng(2)
    axis = filters.constant_velocity(1.0).axis()
    q, T = 0.3, 30
    y = np.cumsum(rng.normal(size=T))
    valid = rng.random(T) > 0.2
    valid[:2] = True
    frames = ws.FrameModel(axis.F, axis.B[:, 0], np.full(T, q), y, valid)
    g = elements(frames, slice(0, 1))
    for t in range(1, T):
        nxt = ws.Elements.empty(1)
        frames.append(g, slice(t, t + 1), nxt)
        g = nxt
    x, P = np.zeros(2), np.eye(2) * 1e14  # a diffuse start one frame before the window
    Q = q * np.outer(axis.B[:, 0], axis.B[:, 0])
    for t in range(T):
        x, P = axis.F @ x, axis.F @ P @ axis.F.T + Q
        if valid[t]:
            K = P[:, 0] / (P[0, 0] + 1.0)
            x, P = x + K * (y[t] - x[0]), P - np.outer(K, P[0])
    np.testing.assert_allclose(ws.flat_prior_estimate(g)[0], x, rtol=1e-8)


@pytest.mark.parametrize("whole_boxes", [True, False])
@pytest.mark.parametrize("name", ["oufir", "ofir", "fir"])
def test_windows_with_missing_samples_equal_a_kf_per_window(name: str, whole_boxes: bool,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Per-track horizons (so block lengths differ per channel), 30 % missing frames (so OFIR meets windows inside
    one block, which run their own KF), missing as whole boxes (the coordinates of a track share one scan) or per
    coordinate (and a third coordinate as a copy of the first: some tracks share, some do not): the scan's
    estimates equal those of the KF run over each window. The numpy scan (the compiled scan's reference, which
    tests/filters/test_fir_kernels.py checks against it)."""
    monkeypatch.setattr(jit, "ENABLED", False)
    rng = np.random.default_rng(3)
    y = 100.0 + np.cumsum(rng.normal(size=(5, 150, 2)), axis=1) * 3
    if whole_boxes:
        y[rng.random((5, 150)) < 0.3] = np.nan
    else:
        y[rng.random((5, 150, 2)) < 0.3] = np.nan
        y = np.concatenate([y, y[..., :1] + 7.0], axis=2)
    model = filters.constant_velocity(1 / 30, ndim=y.shape[2])
    params = {"horizon": np.array([3, 8, 25, 60, 13]), "sigma_w": np.array([5.0, 50.0, 500.0, 20.0, 1.0]),
              "sigma_v": 3.0}
    flt = filters.make(name, model, **params)
    calls = []
    kalman_windows = KalmanWindowFIR._kalman_windows

    def spy(self, X, z, valid, cs, first, emit, last, params):  # noqa: ANN001, ANN202
        calls.append(bool(np.any(first > 0)))  # start-up runs begin at frame 0; per-window runs later
        return kalman_windows(self, X, z, valid, cs, first, emit, last, params)

    monkeypatch.setattr(KalmanWindowFIR, "_kalman_windows", spy)
    scan = flt.run(y)
    if name == "ofir":
        assert any(calls)  # some windows inside one block took the per-window KF

    def per_window(self, X, z, valid, cs, ns, L_w, group, gparams):  # noqa: ANN001, ANN202
        spy(self, X, z, valid, cs, ns - L_w + 1, ns, ns, {k: v[group[cs]] for k, v in gparams.items()})

    monkeypatch.setattr(KalmanWindowFIR, "_masked", per_window)  # the previous method: one KF per window
    reference = flt.run(y)
    assert np.array_equal(np.isnan(scan), np.isnan(reference))
    M = y.shape[2]
    for part in (slice(0, M), slice(M, 2 * M)):
        scale = np.nanmax(np.abs(reference[..., part]))
        assert np.nanmax(np.abs(scan[..., part] - reference[..., part])) <= 1e-11 * scale


def test_the_scan_refuses_windows_shorter_than_the_horizon() -> None:
    """The scan's blocks are one window long: a shorter (start-up) window is an error, not a wrong estimate."""
    flt = filters.make("oufir", filters.constant_velocity(1.0), sigma_w=1.0, sigma_v=1.0, horizon=5)
    z = np.arange(20.0)[None]
    z[0, 3] = np.nan
    X = np.zeros((1, 20, 2))
    gparams = {"horizon": np.array([5]), "sigma_w": np.array([1.0]), "sigma_v": np.array([1.0])}
    with pytest.raises(ValueError, match="full windows"):
        flt._masked(X, z, np.isfinite(z), np.array([0]), np.array([4]), np.array([4]), np.array([0]), gparams)
