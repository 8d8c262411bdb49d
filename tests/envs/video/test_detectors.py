"""Detectors on tiny synthetic videos: they find the object, return NaN when there is nothing, validate."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from bboxtune.envs.data import metrics
from bboxtune.envs.video.detector import MAX_WIDENING
from bboxtune.envs.video.detectors import DETECTORS, detect_video, make_detector
from bboxtune.envs.video.synthetic import VideoScenario, render

SCENE = VideoScenario(width=128, height=96, n_frames=20, object_size=(32.0, 28.0), speed=60.0, noise=2.0, rotation=3.0)


@pytest.fixture(scope="module")
def video():
    v = render(SCENE, seed=2)
    return v, list(v)


@pytest.mark.parametrize("name", DETECTORS)
def test_detector_follows_the_object(name, video):
    v, frames = video
    y = detect_video(make_detector(name), frames, v.boxes[0])
    assert y.shape == (20, 4)
    np.testing.assert_array_equal(y[0], v.boxes[0])  # row 0 is the initial box (OTB protocol)
    iou = np.nan_to_num(metrics.iou(y[5:], v.boxes[5:]))  # missing counts as 0
    assert iou.mean() > 0.5, (name, iou.round(2))


@pytest.mark.parametrize("name", ["template", "sift", "orb", "regions"])
def test_appearance_detectors_return_nan_when_the_object_is_gone(name, video):
    v, frames = video
    det = make_detector(name)
    det.start(frames[0], v.boxes[0])
    blank = np.full_like(frames[0], 127)
    box = det.detect(blank)
    assert box.shape == (4,) and np.all(np.isnan(box))
    assert det.missed == 1


@pytest.mark.parametrize("name", ["bgsub", "mog2"])
def test_background_subtractors_return_nan_on_a_static_scene(name, video):
    _, frames = video
    det = make_detector(name)
    det.start(frames[0], np.array([10.0, 10.0, 20.0, 20.0]))
    boxes = [det.detect(frames[0]) for _ in range(3)]
    assert np.all(np.isnan(boxes))


def test_template_is_subpixel_accurate_on_a_pure_translation(video):
    v, frames = video
    dx, dy = 2.3, -1.6
    moved = cv2.warpAffine(frames[0], np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]]), (128, 96),
                           flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    det = make_detector("template", update=0.0)
    det.start(frames[0], v.boxes[0])
    box = det.detect(moved)
    np.testing.assert_allclose(box[:2], v.boxes[0][:2] + (dx, dy), atol=0.2)
    np.testing.assert_allclose(box[2:], np.rint(v.boxes[0][2:]))


def test_sift_box_follows_a_scaled_object(video):
    v, frames = video
    x, y, w, h = v.boxes[0]
    cx, cy = x + w / 2, y + h / 2
    A = cv2.getRotationMatrix2D((cx - 0.5, cy - 0.5), 0.0, 1.25)  # scale about the object centre
    det = make_detector("sift")
    det.start(frames[0], v.boxes[0])
    box = det.detect(cv2.warpAffine(frames[0], A, (128, 96), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT))
    np.testing.assert_allclose(box[2:], 1.25 * v.boxes[0][2:], rtol=0.08)
    np.testing.assert_allclose(box[:2] + box[2:] / 2, (cx, cy), atol=1.5)


def _jump_video(seed: int):
    """A static 40×32 object in a 480×360 frame, the same frame without it, and the object moved to the far
    corner, beyond the widest window a detector searches before it re-detects (``MAX_WIDENING + 1`` margins
    of the box's larger side)."""
    v = render(VideoScenario(width=480, height=360, n_frames=1, object_size=(40.0, 32.0), speed=0.0, sigma_w=0.0,
                             manoeuvre_rate=0.0, noise=1.0), seed=seed)
    c = v.centres[0]
    shift = np.where(c < (240, 180), (450, 330), (30, 30)) - c
    gone = dataclasses.replace(v, texture=np.zeros_like(v.texture))
    moved = dataclasses.replace(v, centres=v.centres + shift, boxes=v.boxes + np.r_[shift, 0.0, 0.0])
    assert np.any(np.abs(shift) > v.boxes[0, 2:] + (MAX_WIDENING + 1) * v.boxes[0, 2:].max()), seed
    return v, gone, moved


@pytest.mark.parametrize("seed", [0, 1, 7])
@pytest.mark.parametrize("name", ["template", "sift", "orb", "regions"])
def test_a_lost_detector_re_detects_the_object_anywhere(name, seed):
    v, gone, moved = _jump_video(seed)
    det = make_detector(name)
    det.start(v.frame(0), v.boxes[0])
    assert metrics.iou(det.detect(v.frame(0)), v.boxes[0]) > 0.8
    for _ in range(6):  # the object is gone: lost (or a false match in the clutter)
        det.detect(gone.frame(0))
    found = [det.detect(moved.frame(0)) for _ in range(12)]  # it is back, far from where it was lost
    assert metrics.iou(found[-1], moved.boxes[0]) > 0.7, (name, seed, found[-1], moved.boxes[0])


def test_template_follows_the_object_s_scale(video):
    v, frames = video
    x, y, w, h = v.boxes[0]
    centre = (x + w / 2 - 0.5, y + h / 2 - 0.5)  # pixel-centre coordinates of the box centre
    det = make_detector("template", update=0.0)
    det.start(frames[0], v.boxes[0])
    for scale in np.linspace(1.02, 1.3, 15):  # the object grows by 30 % in 15 frames
        A = cv2.getRotationMatrix2D(centre, 0.0, float(scale))
        box = det.detect(cv2.warpAffine(frames[0], A, (128, 96), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT))
    np.testing.assert_allclose(box[2:], 1.3 * np.rint(v.boxes[0][2:]), rtol=0.06)
    np.testing.assert_allclose(box[:2] + box[2:] / 2, (x + w / 2, y + h / 2), atol=1.5)


def test_bad_names_and_parameters_raise():
    with pytest.raises(ValueError, match="surf"):
        make_detector("surf")
    with pytest.raises(ValueError, match="threshold=2"):
        make_detector("template", threshold=2)
    with pytest.raises(ValueError, match="bogus"):
        make_detector("regions", bogus=1)
    with pytest.raises(ValueError, match="n_frames"):
        make_detector("bgsub", n_frames=0)
    with pytest.raises(ValueError, match="scale_step"):
        make_detector("template", scale_step=0.9)
    with pytest.raises(ValueError, match=r"scale_range\[0\]"):
        make_detector("template", scale_range=(1.5, 2.0))
    with pytest.raises(ValueError, match="redetect_after"):
        make_detector("template", redetect_after=0)


def test_initial_box_must_lie_in_the_frame(video):
    _, frames = video
    with pytest.raises(ValueError, match="outside"):
        make_detector("template").start(frames[0], np.array([120.0, 10.0, 30.0, 20.0]))
    with pytest.raises(ValueError, match="w, h >= 4"):
        make_detector("orb").start(frames[0], np.array([10.0, 10.0, 2.0, 20.0]))
    with pytest.raises(ValueError, match="empty"):
        detect_video(make_detector("template"), [], np.array([1.0, 1.0, 8.0, 8.0]))
