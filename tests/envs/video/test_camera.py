"""Camera motion: background shift estimate, compensation for any back end and the UKF's eq. 17 model."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.envs.episodes.video_source import NOMINAL_REL
from bboxtune.envs.video.camera import background_shift, background_velocity, camera_offset, run_compensated
from bboxtune.envs.video.detectors import detect_video, make_detector
from bboxtune.envs.video.synthetic import VideoRanges, synthetic_video

TAU = 1 / 30
CAMERA_VIDEOS = VideoRanges(width=160, height=120, n_frames=60, size=(24.0, 40.0), camera_probability=1.0,
                            camera_motion=(10.0, 20.0), occlusion_probability=0.0)
SEEDS = (3_000_000, 3_000_001, 3_000_002, 3_000_003)  # a fixed seed set, outside the train/val/test splits


def test_background_shift_matches_the_true_camera():
    video = synthetic_video(SEEDS[0], CAMERA_VIDEOS)
    shift = background_shift(video)
    true = -np.diff(video.camera, axis=0, prepend=video.camera[:1])
    assert shift.shape == (60, 2) and np.all(shift[0] == 0)
    assert np.sqrt(np.mean((shift - true) ** 2)) < 0.1  # px per frame
    np.testing.assert_allclose(camera_offset(shift)[-1], video.camera[-1], atol=1.0)


def test_input_compensation_without_camera_motion_is_the_plain_filter():
    y = np.random.default_rng(0).normal(100.0, 3.0, (50, 4))
    plain = filters.make("kf", filters.constant_velocity(TAU, ndim=4), sigma_w=50.0, sigma_v=2.0).run(y)
    np.testing.assert_allclose(run_compensated("kf", y, np.zeros((50, 2)), TAU, sigma_w=50.0, sigma_v=2.0), plain)


@pytest.mark.parametrize("backend", ["kf", "ufir", "ukf"])
def test_static_object_under_a_shaking_camera_is_recovered(backend):
    """Image position = static point − camera; with the shift known, the estimate follows the shake exactly."""
    t = np.arange(90) * TAU
    camera = np.column_stack([8 * np.sin(2 * np.pi * 2.0 * t), 5 * np.sin(2 * np.pi * 1.3 * t + 1.0)])
    noise = np.random.default_rng(1).normal(0.0, 1.0, (90, 4))
    truth = np.column_stack([100.0 - camera, np.full((90, 2), 30.0)])
    shift = -np.diff(camera, axis=0, prepend=camera[:1])
    params = {"sigma_w": 5.0, "sigma_v": 1.0} if backend != "ufir" else {"horizon": 30}
    comp = run_compensated(backend, truth + noise, shift, TAU, **params)[:, :4]
    plain = filters.make(backend, filters.constant_velocity(TAU, ndim=4), **params).run(truth + noise)[:, :4]
    err_comp = np.sqrt(np.mean((comp[20:, :2] - truth[20:, :2]) ** 2))
    err_plain = np.sqrt(np.mean((plain[20:, :2] - truth[20:, :2]) ** 2))
    assert err_comp < 0.8 and err_plain > 3 * err_comp


@pytest.fixture(scope="module")
def detected():
    """Template detections, estimated background shifts and truth (cx, cy, w, h) of the fixed seed set."""
    out = []
    for seed in SEEDS:
        video = synthetic_video(seed, CAMERA_VIDEOS)
        frames = list(video)
        y = xywh_to_cxcywh(detect_video(make_detector("template"), frames, video.boxes[0]))
        out.append((y, background_shift(frames), xywh_to_cxcywh(video.boxes)))
    return out


@pytest.mark.parametrize("smoothing", [1.0, 10.0])
def test_compensation_lowers_rmse_on_camera_motion_videos(detected, smoothing):
    """The must-show of issue 6: on generator videos with camera motion, compensation (camera-velocity input
    for the KF, eq. 17's augmented UKF) lowers the centre RMSE against the same filter without it."""
    rel_v, rel_w = NOMINAL_REL["template"]
    rmse = {m: [] for m in ("kf", "kf+input", "ukf", "ukf8")}
    for y, shift, truth in detected:
        scale = np.sqrt(np.nanmedian(y[:, 2] * y[:, 3]))
        p = {"sigma_w": rel_w * scale, "sigma_v": smoothing * rel_v * scale}
        model = filters.constant_velocity(TAU, ndim=4)
        est = {"kf": filters.make("kf", model, **p).run(y), "kf+input": run_compensated("kf", y, shift, TAU, **p),
               "ukf": filters.make("ukf", model, **p).run(y),
               "ukf8": run_compensated("ukf", y, shift, TAU, **p)}
        for m, e in est.items():
            rmse[m].append(np.sqrt(np.mean(np.sum((e[:, :2] - truth[:, :2]) ** 2, axis=1))))
    mean = {m: float(np.mean(v)) for m, v in rmse.items()}
    assert mean["kf+input"] < mean["kf"] and mean["ukf8"] < mean["ukf"], mean
    assert np.sum(np.array(rmse["kf+input"]) < np.array(rmse["kf"])) >= 3, rmse


def test_run_compensated_checks_shapes():
    with pytest.raises(ValueError, match="shift"):
        run_compensated("kf", np.zeros((10, 4)), np.zeros((9, 2)), TAU)


def test_background_velocity_is_exact_for_a_uniformly_accelerating_camera():
    t = np.arange(12) * TAU
    camera = np.column_stack([0.5 * 300.0 * t**2, -0.5 * 120.0 * t**2 + 40.0 * t])
    shift = -np.diff(camera, axis=0, prepend=camera[:1])
    u = background_velocity(shift, TAU)
    assert np.all(np.isnan(u[0]))
    np.testing.assert_allclose(u[2:], -np.column_stack([300.0 * t, -120.0 * t + 40.0])[2:], atol=1e-9)
