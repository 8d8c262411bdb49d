"""The IMM baseline (bboxtune.agents.policies.imm) against filterpy's IMMEstimator, and its behaviour on manoeuvres and gaps."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

from bboxtune.agents.policies.imm import IMMConfig, imm_positions
from bboxtune.filters.kalman_core import VELOCITY_PRIOR_SCALE


def _filterpy_imm(y: np.ndarray, tau: float, sigma_w: float, sigma_v: float, config: IMMConfig) -> np.ndarray:
    F = np.array([[1.0, tau], [0.0, 1.0]])
    Bv = np.array([[tau**2 / 2], [tau]])
    kfs = []
    for g in config.gains:
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.F, kf.H, kf.R = F, np.array([[1.0, 0.0]]), np.array([[sigma_v**2]])
        kf.Q = (g * sigma_w) ** 2 * Bv @ Bv.T
        kf.x = np.array([[y[0]], [0.0]])
        kf.P = np.diag([sigma_v**2, (VELOCITY_PRIOR_SCALE * sigma_v / tau) ** 2])
        kfs.append(kf)
    s = config.stay
    imm = IMMEstimator(kfs, np.array([0.5, 0.5]), np.array([[s, 1 - s], [1 - s, s]]))
    out = [y[0]]
    for z in y[1:]:
        imm.predict()
        if np.isfinite(z):
            imm.update(np.array([[z]]))
        out.append(float(imm.x[0, 0]))
    return np.array(out)


@pytest.mark.parametrize("config", [IMMConfig(), IMMConfig(gains=(0.3, 3.0), stay=0.9)])
def test_matches_filterpy(config: IMMConfig) -> None:
    rng = np.random.default_rng(0)
    tau, sigma_w, sigma_v = 0.05, 20.0, 3.0
    acc = rng.normal(0, sigma_w, 300)
    acc[100:140] *= 10  # a manoeuvre
    truth = np.cumsum(np.cumsum(acc) * tau) * tau
    y = truth + rng.normal(0, sigma_v, 300)
    ours = imm_positions(y[None, :, None], tau, sigma_w, sigma_v, config)[0, :, 0]
    np.testing.assert_allclose(ours, _filterpy_imm(y, tau, sigma_w, sigma_v, config), rtol=1e-9, atol=1e-7)
    rmse = lambda e: np.sqrt(np.mean((e - truth) ** 2))  # noqa: E731
    assert rmse(ours) < rmse(y)


def test_batch_channels_are_independent_and_gaps_predict() -> None:
    rng = np.random.default_rng(1)
    y = np.cumsum(rng.normal(0, 1, (3, 120, 4)), axis=1)
    y[1, :5, 2] = np.nan  # a channel that starts late
    y[2, 50:60] = np.nan  # a gap
    out = imm_positions(y, np.array([0.05, 0.04, 0.1]), np.array([5.0, 6.0, 7.0]), 1.0)
    assert np.isnan(out[1, :5, 2]).all() and np.isfinite(out[1, 5:, 2]).all() and np.isfinite(out[2]).all()
    for b in range(3):
        one = imm_positions(y[b:b + 1], [0.05, 0.04, 0.1][b], [5.0, 6.0, 7.0][b], 1.0)
        np.testing.assert_allclose(out[b:b + 1], one, rtol=1e-12, equal_nan=True)
    for m in range(4):  # a channel on its own (with filterpy) gives the same estimate up to the gap; in the gap
        ref = _filterpy_imm(y[2, :, m], 0.1, 7.0, 1.0, IMMConfig())  # filterpy keeps μ, we predict it (μ = c̄)
        np.testing.assert_allclose(out[2, :50, m], ref[:50], rtol=1e-9, atol=1e-7)
        assert np.abs(out[2, 100:, m] - ref[100:]).max() < 0.05 * np.abs(out[2, 50:60, m] - ref[50:60]).max()  # re-converge


@pytest.mark.parametrize("config", [IMMConfig(stay=0.5), IMMConfig(stay=1.0), IMMConfig(gains=(0.0, 1.0))])
def test_bad_config_is_refused(config: IMMConfig) -> None:
    with pytest.raises(ValueError, match="stay must lie in"):
        imm_positions(np.zeros((1, 5, 1)), 0.05, 1.0, 1.0, config)
