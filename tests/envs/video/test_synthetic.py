"""The synthetic video generator: determinism, exact boxes, camera offsets, validation."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from bboxtune.envs.video.synthetic import VideoRanges, VideoScenario, render, synthetic_video

TINY = VideoScenario(width=64, height=64, n_frames=30, object_size=(16.0, 14.0), speed=40.0, noise=0.0)


def object_mask(frame: np.ndarray, hue: float) -> np.ndarray:
    hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV).astype(int)
    dist = np.minimum(np.abs(hsv[..., 0] - hue), 180 - np.abs(hsv[..., 0] - hue))
    return (dist <= 6) & (hsv[..., 1] > 70)


def test_same_seed_same_video_and_frames_by_random_access():
    a, b = render(TINY, seed=3), render(TINY, seed=3)
    np.testing.assert_array_equal(a.boxes, b.boxes)
    frames = list(a)
    assert len(frames) == 30 and frames[0].shape == (64, 64, 3) and frames[0].dtype == np.uint8
    np.testing.assert_array_equal(frames[17], b.frame(17))
    c = render(TINY, seed=4)
    assert not np.allclose(a.boxes, c.boxes)


@pytest.mark.parametrize("rotation, deformation", [(0.0, 0.0), (20.0, 0.1)])
def test_ground_truth_box_is_the_rendered_object(rotation, deformation):
    sc = replace(TINY, width=96, height=80, object_size=(24.0, 18.0), rotation=rotation, deformation=deformation,
                 scale_change=0.2, camera_motion=6.0)
    video = render(sc, seed=1)
    first = video.frame(0)
    x, y, w, h = video.boxes[0]
    hue = float(np.median(cv2.cvtColor(first, cv2.COLOR_BGR2HSV)[int(y + h / 2), int(x + w / 2) - 2:int(x + w / 2) + 2, 0]))
    for t in (0, 11, 29):
        ys, xs = np.nonzero(object_mask(video.frame(t), hue))
        measured = np.array([xs.min(), ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()], dtype=float)
        np.testing.assert_allclose(measured, video.boxes[t], atol=1.5)


def test_object_stays_inside_the_frame_under_camera_motion():
    sc = replace(TINY, camera_motion=20.0, speed=200.0, manoeuvre_rate=3.0, manoeuvre_accel=500.0, n_frames=120)
    video = render(sc, seed=7)
    x, y, w, h = video.boxes.T
    assert np.all(x >= 0) and np.all(y >= 0) and np.all(x + w <= 64) and np.all(y + h <= 64)
    assert np.abs(video.camera).max() > 1.0 and np.all(video.camera[0] == 0)


def test_camera_offset_moves_the_background():
    """A static scene point seen at q_t satisfies q_t + camera_t = const: compare frames by phase correlation."""
    sc = replace(TINY, width=128, height=96, camera_motion=15.0, object_size=(10.0, 10.0), n_frames=20)
    video = render(sc, seed=2)
    g0, g1 = (cv2.cvtColor(video.frame(t), cv2.COLOR_BGR2GRAY).astype(np.float32) for t in (0, 19))
    shift, _ = cv2.phaseCorrelate(g0, g1)
    np.testing.assert_allclose(shift, -(video.camera[19] - video.camera[0]), atol=0.5)


def test_ranges_give_seeded_variety():
    videos = [synthetic_video(s, VideoRanges(width=64, height=64, n_frames=10, size=(12.0, 20.0))) for s in range(8)]
    cams = [v.scenario.camera_motion > 0 for v in videos]
    assert any(cams) and not all(cams)
    assert len({v.scenario.object_size for v in videos}) == 8
    again = synthetic_video(5, VideoRanges(width=64, height=64, n_frames=10, size=(12.0, 20.0)))
    assert again.scenario == videos[5].scenario


@pytest.mark.parametrize("field, value", [("n_frames", 0), ("fps", -1.0), ("object_size", (40.0, 10.0)),
                                          ("illumination", 1.5), ("manoeuvre_duration", (0.5, 0.1))])
def test_bad_scenario_raises_naming_the_field(field, value):
    name = field.split("[")[0]
    with pytest.raises(ValueError, match=name):
        replace(TINY, **{field: value})


def test_frame_index_out_of_range():
    with pytest.raises(ValueError, match="t=30"):
        render(TINY, 0).frame(30)
