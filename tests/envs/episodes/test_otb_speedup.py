"""``otb_speedup_max``: OTB training episodes played at a random frame stride (an augmentation for fast motion)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune.envs.data.otb import OTBDataset, replay_synthetic, replay_tracker
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.sources import SPEEDUP_MIN_FRAMES, OTBSource
from tests.envs.conftest import OTB_ROOT, needs_otb


@pytest.mark.parametrize("kwargs, error, match", [
    ({"source": "otb", "otb_speedup_max": 0}, ValueError, r"otb_speedup_max=0 .*\[1, 8\]"),
    ({"source": "otb", "otb_speedup_max": 9}, ValueError, r"otb_speedup_max=9 .*\[1, 8\]"),
    ({"source": "otb", "otb_speedup_max": 2.0}, TypeError, "otb_speedup_max"),
    ({"source": "otb", "otb_speedup_max": True}, TypeError, "otb_speedup_max"),
    ({"source": "sim", "otb_speedup_max": 2}, ValueError, "otb_speedup_max=2 with source='sim'"),
    ({"source": "video", "otb_speedup_max": 3}, ValueError, "only with source 'otb', 'otb_tracker', 'mix' .* or 'mot'"),
])
def test_bad_speedup_is_named(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        EnvConfig(**kwargs)


@needs_otb
@pytest.mark.parametrize("source", ["otb", "otb_tracker"])
def test_training_episodes_play_every_kth_frame(source: str) -> None:
    dataset = OTBDataset(OTB_ROOT)
    src = OTBSource(EnvConfig(source=source, otb_root=OTB_ROOT, otb_speedup_max=4), dataset)
    strides = []
    for seed in range(24):
        episode = src.draw(None, seed)
        meta = episode.meta
        k, j = meta["stride"], meta["offset"]
        strides.append(k)
        assert 1 <= k <= 4 and 0 <= j < k
        gt = dataset.groundtruth(meta["sequence"])[j::k]
        if source == "otb":
            rng = np.random.default_rng((seed, 1))
            psi, sigma_rel = rng.uniform(*src.cfg.psi_range), np.exp(rng.uniform(*np.log(src.cfg.cmn_rel_range)))
            expected = replay_synthetic(gt, psi=psi, sigma_rel=sigma_rel, rng=rng, tau=src.cfg.otb_tau)
            assert episode.scenario == {"psi": psi, "sigma_rel": sigma_rel}
        else:
            boxes = dataset.tracker_boxes(meta["tracker"], meta["sequence"])[j::k]
            expected = replay_tracker(gt, boxes, tau=src.cfg.otb_tau)
        np.testing.assert_array_equal(episode.truth, expected.truth)
        np.testing.assert_array_equal(episode.y, expected.y)
        assert len(episode.y) >= SPEEDUP_MIN_FRAMES or k == 1
    assert {1, 2, 3, 4} <= set(strides)  # every stride occurs in 24 draws (seeded: not a flaky count)


@needs_otb
def test_short_sequences_keep_enough_frames() -> None:
    dataset = OTBDataset(OTB_ROOT)
    src = OTBSource(EnvConfig(source="otb", otb_root=OTB_ROOT, otb_speedup_max=8), dataset)
    for name in src.sequences[:12]:
        n = len(dataset.groundtruth(name))
        for seed in range(4):
            episode = src.draw(name, seed)
            assert len(episode.y) >= min(n, SPEEDUP_MIN_FRAMES)
            assert episode.meta["stride"] == 1 or len(episode.y) >= SPEEDUP_MIN_FRAMES


@needs_otb
@pytest.mark.parametrize("split", ["val", "test"])
def test_val_and_test_play_every_frame(split: str) -> None:
    kwargs = dict(source="otb", split=split, otb_root=OTB_ROOT)
    plain = gym.make("bboxtune/FilterTune-v0", **kwargs)
    sped = gym.make("bboxtune/FilterTune-v0", otb_speedup_max=4, **kwargs)
    for seed in range(3):
        obs, info = plain.reset(seed=seed)
        obs_sped, info_sped = sped.reset(seed=seed)
        assert info_sped["track"] == info["track"] and "stride" not in info["track"]
        np.testing.assert_array_equal(obs_sped, obs)


@needs_otb
def test_default_leaves_training_episodes_unchanged() -> None:
    plain = OTBSource(EnvConfig(source="otb", otb_root=OTB_ROOT))
    stride1 = OTBSource(EnvConfig(source="otb", otb_root=OTB_ROOT, otb_speedup_max=1))
    for seed in range(3):
        a, b = plain.draw(None, seed), stride1.draw(None, seed)
        assert "stride" not in a.meta and a.meta == b.meta
        np.testing.assert_array_equal(a.y, b.y)
        assert len(a.y) == len(plain.dataset.groundtruth(a.meta["sequence"]))


@needs_otb
def test_mix_speeds_up_its_otb_parts_only() -> None:
    env = gym.make("bboxtune/FilterTune-v0", source="mix", otb_root=OTB_ROOT, otb_speedup_max=3, track_length=64)
    parts = {}
    for seed in range(12):
        _, info = env.reset(seed=seed)
        track = info["track"]
        parts.setdefault(track["source"], []).append("stride" in track)
    assert set(parts) == {"sim", "otb", "otb_tracker"}  # seeded: every part occurs
    assert not any(parts["sim"]) and all(parts["otb"]) and all(parts["otb_tracker"])
