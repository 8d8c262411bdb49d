from __future__ import annotations

import numpy as np
import pytest

from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.data.otb import replay_synthetic, replay_tracker


def gt_boxes(T: int = 400) -> np.ndarray:
    t = np.arange(T, dtype=float)
    return np.stack([100 + t, 50 + 0.5 * t, 40 + 20 * np.sin(t / 50), 30 + 0 * t], axis=1)


def test_boxes_round_trip_and_centre():
    b = np.array([[10.0, 20.0, 4.0, 6.0], [np.nan] * 4])
    np.testing.assert_array_equal(xywh_to_cxcywh(b)[0], [12.0, 23.0, 4.0, 6.0])
    np.testing.assert_array_equal(cxcywh_to_xywh(xywh_to_cxcywh(b)), b)
    with pytest.raises(ValueError, match="shape"):
        xywh_to_cxcywh([1, 2, 3])


def test_synthetic_noise_is_gauss_markov_scaled_to_the_box():
    gt = gt_boxes(20000)
    tr = replay_synthetic(gt, psi=0.9, sigma_rel=0.02, rng=np.random.default_rng(0))
    truth = xywh_to_cxcywh(gt)
    np.testing.assert_array_equal(tr.truth, truth)
    u_cx = (tr.y[:, 0] - truth[:, 0]) / truth[:, 2]  # centre noise in units of the box width
    u_h = np.log(tr.y[:, 3] / truth[:, 3])  # size noise in log space
    for u in (u_cx, u_h):
        assert u.std() == pytest.approx(0.02 / np.sqrt(1 - 0.81), rel=0.1)
        assert np.corrcoef(u[:-1], u[1:])[0, 1] == pytest.approx(0.9, abs=0.02)
    assert np.all(tr.y[:, 2:] > 0)
    again = replay_synthetic(gt, psi=0.9, sigma_rel=0.02, rng=np.random.default_rng(0))
    np.testing.assert_array_equal(again.y, tr.y)


def test_synthetic_missing_ground_truth_has_no_measurement():
    gt = gt_boxes(10)
    gt[-1] = np.nan
    tr = replay_synthetic(gt, psi=0.0, sigma_rel=0.05, rng=np.random.default_rng(1), tau=0.04)
    assert np.isnan(tr.truth[-1]).all() and np.isnan(tr.y[-1]).all() and np.isfinite(tr.y[:-1]).all()
    assert tr.tau == 0.04 and tr.truth_state.shape == (10, 8)


def test_tracker_replay_and_velocities():
    gt = gt_boxes(6)
    meas = gt + 1.0
    meas[2] = np.nan
    tr = replay_tracker(gt, meas, tau=0.5)
    np.testing.assert_array_equal(tr.y[[0, 1, 3]], xywh_to_cxcywh(meas)[[0, 1, 3]])
    assert np.isnan(tr.y[2]).all()
    np.testing.assert_allclose(tr.truth_state[1:, 4], np.diff(tr.truth[:, 0]) / 0.5)  # backward differences
    np.testing.assert_array_equal(tr.truth_state[0, 4:], tr.truth_state[1, 4:])


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda gt: replay_synthetic(gt, psi=1.0, sigma_rel=0.1, rng=np.random.default_rng()), "psi"),
        (lambda gt: replay_synthetic(gt, psi=0.5, sigma_rel=0.0, rng=np.random.default_rng()), "sigma_rel"),
        (lambda gt: replay_synthetic(gt[:, :3], psi=0.5, sigma_rel=0.1, rng=np.random.default_rng()), "shape"),
        (lambda gt: replay_tracker(gt, gt[:-1]), "match"),
        (lambda gt: replay_tracker(gt, gt, tau=0.0), "tau"),
        (lambda gt: replay_tracker(gt * [1, 1, 0, 1], gt), "w, h > 0"),
    ],
)
def test_replay_rejects_bad_input(call, message):
    with pytest.raises(ValueError, match=message):
        call(gt_boxes(5))
