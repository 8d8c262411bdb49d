"""source="mot": MOT15 identity episodes (bboxtune.envs.episodes.mot_source) on hand-made identities and, with MOT_ROOT,
the data."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs  # noqa: F401  (registers the env ids)
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.envs.data.mot import MOTIdentity
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.mot_source import STRIDED_MIN_FRAMES, MOTSource, identity_episode

TRAIN, TEST = "Venice-2", "KITTI-13"  # parts of the OTB split rule (bboxtune.envs.data.mot.split)


def identity(sequence: str, ident: int, T: int = 60, fps: float = 30.0,
             missing: tuple[int, ...] = (0, 1, 7, 8, 9)) -> MOTIdentity:
    t = np.arange(T, dtype=float)
    truth = np.stack([100 + 3 * t, 50 + t, np.full(T, 20.0), np.full(T, 50.0)], axis=1)
    measured = truth + 0.5
    measured[list(missing)] = np.nan
    measured[T - 2:] = np.nan  # the span ends at the last detection
    scores = np.where(np.isfinite(measured[:, 0]), 1.0, np.nan)
    return MOTIdentity(sequence=sequence, identity=ident, first_frame=5, truth=truth, measured=measured,
                       scores=scores, tau=1.0 / fps)


POOL = (identity(TRAIN, 1, T=100), identity(TRAIN, 2, T=40), identity(TEST, 3))


def test_episode_is_the_detected_span_in_cxcywh() -> None:
    ident = POOL[0]
    ep = identity_episode(EnvConfig(source="mot"), ident)
    assert len(ep.y) == 100 - 2 - 2  # frames 2 .. 97
    np.testing.assert_array_equal(ep.y[0], xywh_to_cxcywh(ident.measured[2]))
    np.testing.assert_array_equal(ep.truth, xywh_to_cxcywh(ident.truth[2:98]))
    assert np.isnan(ep.y[5:8]).all() and ep.tau == pytest.approx(1 / 30)
    assert ep.meta == {"sequence": "Venice-2/1", "noise_seed": 0, "tau": ep.tau, "first_frame": 7}
    assert ep.nominal.sigma_v == pytest.approx(0.03 * np.sqrt(20.5 * 50.5))  # otb_sigma_v_rel × measured box scale


def test_pool_is_the_split_and_draws_are_seeded() -> None:
    source = MOTSource(EnvConfig(source="mot"), identities=POOL)
    assert source.sequences == ("Venice-2/1", "Venice-2/2")
    assert MOTSource(EnvConfig(source="mot", split="test"), identities=POOL).sequences == ("KITTI-13/3",)
    first = source.draw(None, 11)
    again = source.draw(None, 11)
    np.testing.assert_array_equal(first.y, again.y)
    assert source.draw("Venice-2/2", 3).meta["sequence"] == "Venice-2/2"
    with pytest.raises(ValueError, match="not a MOT identity of split 'train'"):
        source.draw("KITTI-13/3", 0)
    source.require_frames(50, "a test")
    assert source.sequences == ("Venice-2/1",)
    with pytest.raises(ValueError, match="has 36 frames"):
        source.draw("Venice-2/2", 0)
    with pytest.raises(ValueError, match="no MOT identity of split 'train' has the 100 frames"):
        source.require_frames(100, "a test")
    with pytest.raises(ValueError, match="no MOT identities in split 'val'"):
        MOTSource(EnvConfig(source="mot", split="val"), identities=POOL)


def test_strided_episodes_play_lower_frame_rates_on_train_only() -> None:
    cfg = EnvConfig(source="mot", otb_speedup_max=3)
    source = MOTSource(cfg, identities=POOL)
    strides = set()
    for seed in range(40):
        ep = source.draw("Venice-2/1", seed)
        k = ep.meta.get("stride", 1)
        strides.add(k)
        assert ep.tau == pytest.approx(k / 30)
        assert len(ep.y) >= STRIDED_MIN_FRAMES
        assert np.isfinite(ep.y[[0, -1]]).all()  # cut to the first and last detection again
        if k > 1:
            np.testing.assert_array_equal(ep.truth[1] - ep.truth[0], [3 * k, k, 0, 0])
    assert strides == {1, 2, 3}
    test_source = MOTSource(EnvConfig(source="mot", split="test", otb_speedup_max=3), identities=POOL)
    assert all("stride" not in test_source.draw(None, s).meta for s in range(10))


def test_holdout_fold_trains_on_the_other_sequences_at_strides() -> None:
    # the split rule's test sequence held out: the fold trains on the rest; its own test part is the held-out one
    cfg = EnvConfig(source="mot", mot_holdout=TEST, otb_speedup_max=3)
    train = MOTSource(cfg, identities=POOL)
    assert train.sequences == ("Venice-2/1", "Venice-2/2")
    assert MOTSource(EnvConfig(source="mot", mot_holdout=TEST, split="val"), identities=POOL).sequences == train.sequences
    held_out = MOTSource(EnvConfig(source="mot", mot_holdout=TEST, split="test", otb_speedup_max=3), identities=POOL)
    assert held_out.sequences == ("KITTI-13/3",)
    assert {train.draw("Venice-2/1", s).meta.get("stride", 1) for s in range(40)} == {1, 2, 3}
    # a train-rule sequence held out is the fold's test part
    assert MOTSource(EnvConfig(source="mot", mot_holdout=TRAIN, split="test"), identities=POOL).sequences == \
        ("Venice-2/1", "Venice-2/2")
    assert all("stride" not in held_out.draw(None, s).meta for s in range(10))
    with pytest.raises(ValueError, match=r"mot_holdout='KITTI-14' is not a sequence of the MOT data; allowed: "
                                         r"\['KITTI-13', 'Venice-2'\]"):
        MOTSource(EnvConfig(source="mot", mot_holdout="KITTI-14"), identities=POOL)


@pytest.mark.parametrize("kwargs", [{"mot_holdout": "KITTI-13"}, {"source": "mix", "mot_holdout": "KITTI-13"},
                                    {"source": "mot", "mot_holdout": ""}, {"source": "mot", "mot_holdout": 13}])
def test_config_refuses_a_holdout_it_would_not_use(kwargs) -> None:
    with pytest.raises(ValueError, match=r"mot_holdout=.* allowed only with source 'mot', a sequence name"):
        EnvConfig(**kwargs)


def test_config_refuses_mot_root_with_another_source() -> None:
    with pytest.raises(ValueError, match="mot_root='x' with source='sim'"):
        EnvConfig(mot_root="x")
    assert EnvConfig(source="mot", otb_speedup_max=2).otb_speedup_max == 2


def test_env_on_the_data(mot_root) -> None:
    env = gym.make("bboxtune/FilterTune-v0", source="mot", mot_root=str(mot_root), backend="kf_cmn",
                   reward="success_auc")
    assert len(env.unwrapped.source.sequences) == 51
    obs, info = env.reset(seed=0)
    assert np.isfinite(obs).all() and "/" in info["track"]["sequence"]
    _, reward, terminated, _, step_info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert terminated and np.isfinite(reward)
    assert step_info["rule_success_auc"] > 0.3
