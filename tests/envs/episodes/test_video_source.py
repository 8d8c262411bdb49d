"""VideoSource: episodes from detector output on synthetic videos, pinned by name, cached in memory / on disk."""

from __future__ import annotations

import numpy as np
import pytest

import bboxtune.envs.episodes.video_source as source_mod
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.video_source import VideoSettings, VideoSource, detected_video, parse_sequence

SETTINGS = VideoSettings(detector="template", video_pool=3, video_size=(128, 96))


def make(split: str = "test", settings: VideoSettings = SETTINGS) -> VideoSource:
    return VideoSource(EnvConfig(split=split, track_length=24), settings)


def test_episode_is_a_pure_function_of_sequence_and_seed():
    src = make()
    a, b = src.draw("test-00001", 5), make().draw("test-00001", 99)
    np.testing.assert_array_equal(a.y, b.y)  # the detector is deterministic: the noise seed only picks a video
    assert a.truth.shape == a.y.shape == (24, 4) and a.tau == pytest.approx(1 / 30)
    np.testing.assert_allclose(a.y[0], a.truth[0])  # frame 0 = initial box (cx, cy, w, h)
    assert a.meta["sequence"] == "test-00001" and a.meta["detector"] == "template"
    n = a.nominal
    assert n.sigma_v > 0 and n.sigma_w > 0 and 2 <= n.horizon <= 400
    picked = {src.draw(None, s).meta["sequence"] for s in range(12)}
    assert picked <= set(src.names) and len(picked) > 1
    assert src.draw(None, 7).meta["sequence"] == make().draw(None, 7).meta["sequence"]


def test_splits_hold_different_videos():
    test, train = make("test").draw("test-00000", 0), make("train").draw("train-00000", 0)
    assert not np.allclose(test.truth, train.truth)


@pytest.mark.parametrize("name", ["train-00000", "test-00003", "test-x", "video-1"])
def test_foreign_or_malformed_sequence_raises(name):
    with pytest.raises(ValueError, match="sequence"):
        make().draw(name, 0)


def test_parse_sequence():
    assert parse_sequence("val-00012") == ("val", 12)


def test_disk_cache_is_reused(tmp_path, monkeypatch):
    kwargs = dict(seed=2_000_000, detector="template", n_frames=12, size=(128, 96), cache=tmp_path)
    first = detected_video(**kwargs)
    files = list((tmp_path / "template").glob("2000000-*.npz"))
    assert len(files) == 1
    monkeypatch.setattr(source_mod, "_MEMORY", {})
    monkeypatch.setattr(source_mod, "synthetic_video", lambda *a, **k: pytest.fail("re-rendered despite the cache"))
    again = detected_video(**kwargs)
    for key in ("truth", "y", "camera"):
        np.testing.assert_array_equal(first[key], again[key])
    other = dict(kwargs, n_frames=13)
    monkeypatch.undo()
    detected_video(**other)
    assert len(list((tmp_path / "template").glob("2000000-*.npz"))) == 2  # a different key, a different file


def test_settings_from_config_and_validation():
    class Cfg:
        detector = "orb"
        video_pool = 7
        split = "val"

    s = VideoSettings.from_config(Cfg())
    assert s.detector == "orb" and s.video_pool == 7 and s.video_cache is None
    assert s.nominal_rel == source_mod.NOMINAL_REL["orb"]
    assert VideoSettings(video_sigma_v_rel=0.2).nominal_rel[0] == 0.2
    for bad in ({"detector": "surf"}, {"video_pool": 0}, {"video_size": (32, 32)}, {"video_sigma_w_rel": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            VideoSettings(**bad)
