"""Tracker sets (``trackers``, the ``tracker`` reset option, ``TRACKER_SPLIT``) and the mixed source (``mix``)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from bboxtune.envs.data.otb import TRACKER_SPLIT, OTBDataset, split
from bboxtune.envs.episodes.config import MIX_SOURCES, EnvConfig
from tests.envs.conftest import OTB_ROOT, needs_otb

TUNE, RETUNE = "bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"
TRIPLE = MIX_SOURCES[:3]  # the parts of a (sim, otb, otb_tracker) mix; the mot part: tests/envs/test_mix_mot.py
HELD_OUT = ("SiamRPN++", "CFNet", "STRUCK", "MDNet")


def _otb(env_id: str = TUNE, **kw) -> gym.Env:
    return gym.make(env_id, otb_root=OTB_ROOT, backend=kw.pop("backend", "ufir_cmn"), **kw)


def _episode(env: gym.Env, options: dict | None = None, seed: int | None = None) -> tuple:
    """Everything an agent gets from one episode (reset and one step with a fixed action), comparable with ==."""
    obs, info = env.reset(seed=seed, options=options)
    _, reward, *_, step = env.step(np.full(env.action_space.shape, 0.2, np.float32))
    return obs.tobytes(), info["track"], reward, step["rule_rmse"], step.get("scenario")


def _pins(track: dict) -> dict:
    return {k: track[k] for k in ("sequence", "noise_seed", "tracker") if track.get(k) is not None}


# --- configuration ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, error, match", [
    ({"source": "otb_tracker", "trackers": "SiamFC"}, TypeError, "trackers"),
    ({"source": "otb_tracker", "trackers": ("SiamFC", 3)}, TypeError, "trackers"),
    ({"source": "otb_tracker", "trackers": ("SiamFC", "")}, TypeError, "trackers"),
    ({"source": "otb_tracker", "trackers": ()}, ValueError, "trackers"),
    ({"source": "otb_tracker", "trackers": ("SiamFC", "SiamFC")}, ValueError, "at most once"),
    ({"source": "sim", "trackers": ("SiamFC",)}, ValueError, "trackers=.*source='sim'"),
    ({"source": "otb", "trackers": ("SiamFC",)}, ValueError, "trackers=.*source='otb'"),
    ({"source": "mix", "trackers": ("SiamFC",), "mix_weights": (1, 1, 0)}, ValueError, r"mix_weights\[2\]"),
    ({"source": "mix", "mix_weights": (1, 1)}, TypeError, "mix_weights"),
    ({"source": "mix", "mix_weights": "111"}, TypeError, "mix_weights"),
    ({"source": "mix", "mix_weights": (1, -1, 1)}, ValueError, r"mix_weights\[1\]"),
    ({"source": "mix", "mix_weights": (1, float("inf"), 1)}, ValueError, r"mix_weights\[1\]"),
    ({"source": "mix", "mix_weights": (float("nan"), 1, 1)}, ValueError, r"mix_weights\[0\]"),
    ({"source": "mix", "mix_weights": (0, 0, 0)}, ValueError, "positive sum"),
    ({"source": "mix", "mix_weights": (1, True, 1)}, TypeError, r"mix_weights\[1\]"),
    ({"source": "sim", "mix_weights": (1, 0, 0)}, ValueError, "mix_weights=.*only with source 'mix'"),
])
def test_bad_tracker_and_mix_arguments_are_named(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        EnvConfig(**kwargs)


def test_defaults_and_normalised_values() -> None:
    cfg = EnvConfig()
    assert cfg.trackers is None and cfg.mix_weights == (1.0, 1.0, 1.0)
    cfg = EnvConfig(source="mix", trackers=["CFNet", "MDNet"], mix_weights=np.array([2, 0, 1]))
    assert cfg.trackers == ("CFNet", "MDNet") and cfg.mix_weights == (2.0, 0.0, 1.0)


@needs_otb
def test_unknown_tracker_names_list_the_available_ones() -> None:
    with pytest.raises(ValueError, match=r"trackers=.*\['Nope'\].*'SiamFC'"):
        _otb(source="otb_tracker", trackers=("STRUCK", "Nope"))
    with pytest.raises(ValueError, match=r"tracker='Nope'.*'SiamFC'"):
        _otb(source="otb_tracker", tracker="Nope")


@needs_otb
def test_tracker_split_covers_the_trackers_and_holds_out_four() -> None:
    assert TRACKER_SPLIT["test"] == HELD_OUT and len(TRACKER_SPLIT["train"]) == 9
    assert not set(TRACKER_SPLIT["train"]) & set(TRACKER_SPLIT["test"])
    assert sorted(TRACKER_SPLIT["train"] + TRACKER_SPLIT["test"]) == sorted(OTBDataset(OTB_ROOT).trackers)


# --- tracker sets ---------------------------------------------------------------------------------------------------
@needs_otb
@pytest.mark.parametrize("env_id", [TUNE, RETUNE])
def test_one_tracker_set_equals_the_tracker_field(env_id: str) -> None:
    """trackers=None is (tracker,): the same episodes, seeded or pinned, as an explicit one-tracker set."""
    for tracker in ("SiamFC", "MEEM"):
        plain, one = _otb(env_id, source="otb_tracker", tracker=tracker), _otb(env_id, source="otb_tracker", trackers=(tracker,))
        assert plain.unwrapped.source.trackers == one.unwrapped.source.trackers == (tracker,)
        assert [_episode(plain, seed=3)] + [_episode(plain) for _ in range(3)] == \
            [_episode(one, seed=3)] + [_episode(one) for _ in range(3)]
        assert _episode(plain, {"noise_seed": 5, "tracker": tracker}) == _episode(one, {"noise_seed": 5})


@needs_otb
def test_sources_expose_their_sequences_and_trackers() -> None:
    names = split(OTBDataset(OTB_ROOT).names)
    otb = _otb(source="otb", split="test").unwrapped.source
    assert otb.trackers == () and otb.sequences == names["test"]
    retune = _otb(RETUNE, source="otb", split="test").unwrapped.source  # two windows of 50 frames
    assert set(retune.sequences) == set(names["test"]) - {"Deer", "Football1", "KiteSurf", "Skiing"}
    tracked = _otb(source="otb_tracker", trackers=("MEEM", "STRUCK")).unwrapped.source
    data = tracked.dataset
    assert tracked.trackers == ("MEEM", "STRUCK") and tracked.sequences == names["train"]
    assert tracked.sequences_of("MEEM") == tuple(n for n in names["train"] if n in data.tracker_sequences("MEEM"))
    assert len(tracked.sequences_of("MEEM")) == 36 < len(tracked.sequences_of("STRUCK")) == 55


@needs_otb
def test_tracker_is_drawn_per_episode_reproducibly() -> None:
    trackers = ("MEEM", "STRUCK", "SiamFC")
    env = _otb(source="otb_tracker", trackers=trackers)
    tracks = [_episode(env, seed=9)] + [_episode(env) for _ in range(39)]
    again = _otb(source="otb_tracker", trackers=trackers)
    assert tracks == [_episode(again, seed=9)] + [_episode(again) for _ in range(39)]
    source = env.unwrapped.source
    for _, track, *_ in tracks:
        seed = track["noise_seed"]  # the documented generators: tracker from (seed, 2), sequence from (seed, 0)
        assert track["tracker"] == trackers[np.random.default_rng((seed, 2)).integers(3)]
        pool = source.sequences_of(track["tracker"])
        assert track["sequence"] == pool[np.random.default_rng((seed, 0)).integers(len(pool))]
    assert {t[1]["tracker"] for t in tracks} == set(trackers)
    for episode in tracks[:5]:  # the meta replays the episode, bit for bit
        assert _episode(env, _pins(episode[1])) == episode


@needs_otb
def test_tracker_option_pins_the_tracker_and_is_checked() -> None:
    env = _otb(source="otb_tracker", trackers=("MEEM", "STRUCK"))
    for seed in range(6):
        _, info = env.reset(options={"noise_seed": seed, "tracker": "MEEM"})
        assert info["track"]["tracker"] == "MEEM" and info["track"]["sequence"] in env.unwrapped.source.sequences_of("MEEM")
    missing = next(n for n in env.unwrapped.source.sequences if n not in env.unwrapped.source.sequences_of("MEEM"))
    for seed in range(6):  # a pinned sequence re-draws the tracker until it has output for it
        assert env.reset(options={"noise_seed": seed, "sequence": missing})[1]["track"]["tracker"] == "STRUCK"
    env.reset(options={"noise_seed": 1, "tracker": "STRUCK"})
    current = env.unwrapped.episode
    for bad, error, match in (({"tracker": "SiamFC"}, ValueError, r"options\['tracker'\]='SiamFC'.*'MEEM'"),
                              ({"tracker": 3}, TypeError, r"options\['tracker'\]"),
                              ({"tracker": "MEEM", "sequence": missing}, ValueError, "MEEM.*no output")):
        with pytest.raises(error, match=match):
            env.reset(options=bad)
    assert env.unwrapped.episode is current  # a rejected reset left the episode alone
    for kwargs in ({"source": "otb"}, {"source": "sim", "track_length": 100}, {"source": "mix", "mix_weights": (1, 1, 0)}):
        with pytest.raises(ValueError, match=r"options\['tracker'\].*no trackers"):
            _otb(**kwargs).reset(options={"tracker": "MEEM"})


# --- mix ----------------------------------------------------------------------------------------------------------
@needs_otb
@pytest.mark.parametrize("weights", [(1.0, 1.0, 1.0), (1.0, 3.0, 0.0), (0.5, 0.2, 2.0)])
def test_mix_draws_each_part_with_its_weight(weights: tuple) -> None:
    source = _otb(source="mix", mix_weights=weights).unwrapped.source
    n = 6000
    counts = np.array([sum(source.part_of(seed) == part for seed in range(n)) for part in TRIPLE])
    p = np.array(weights) / sum(weights)
    assert np.all(np.abs(counts - n * p) <= 4 * np.sqrt(n * p * (1 - p)) + 1e-9)  # 4 binomial std, fixed seeds
    assert set(source.parts) == {part for part, w in zip(TRIPLE, weights, strict=False) if w > 0}


@needs_otb
@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn"])
@pytest.mark.parametrize("env_id", [TUNE, RETUNE])
def test_checkers_pass_on_mix_and_tracker_sets(env_id: str, backend: str) -> None:
    for kwargs in ({"source": "mix", "track_length": 120, "window": 30, "mix_weights": (1, 1, 2)},
                   {"source": "otb_tracker", "trackers": TRACKER_SPLIT["train"], "window": 30}):
        env = _otb(env_id, backend=backend, **kwargs)
        gym_check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(env.unwrapped, warn=True)


@needs_otb
@pytest.mark.parametrize("env_id", [TUNE, RETUNE])
def test_a_mix_episode_is_its_parts_episode(env_id: str) -> None:
    # ufir_cmn: bit-identical in any batch (the Kalman family's batched BLAS products round by batch width)
    mix = _otb(env_id, source="mix", trackers=("STRUCK", "MDNet"), track_length=200, backend="ufir_cmn")
    parts = {part: _otb(env_id, source=part, track_length=200, backend="ufir_cmn",
                        **({"trackers": ("STRUCK", "MDNet")} if part == "otb_tracker" else {})) for part in TRIPLE}
    for name in ("observation_space", "action_space"):
        assert all(getattr(mix, name) == getattr(env, name) for env in parts.values())
    seen = set()
    for i in range(12):
        episode = _episode(mix, seed=4) if i == 0 else _episode(mix)
        part = episode[1].pop("source")
        seen.add(part)
        assert part == mix.unwrapped.source.part_of(episode[1]["noise_seed"])
        assert episode == _episode(parts[part], {"noise_seed": episode[1]["noise_seed"]})  # nominal, rule, scenario: the part's
    assert seen == set(TRIPLE)


@needs_otb
def test_mix_pins_replay_and_refuse_what_the_drawn_part_lacks() -> None:
    env = _otb(source="mix", track_length=200)
    source = env.unwrapped.source
    seeds = {part: next(s for s in range(100) if source.part_of(s) == part) for part in TRIPLE}
    for part, seed in seeds.items():  # unpinned = pinned by its meta
        episode = _episode(env, {"noise_seed": seed})
        assert episode[1]["source"] == part and _episode(env, _pins(episode[1])) == episode
    with pytest.raises(ValueError, match=r"options\['sequence'\]='Car4': noise_seed=\d+ draws a 'sim' episode"):
        env.reset(options={"noise_seed": seeds["sim"], "sequence": "Car4"})
    with pytest.raises(ValueError, match=r"options\['tracker'\]='SiamFC': noise_seed=\d+ draws a 'otb' episode"):
        env.reset(options={"noise_seed": seeds["otb"], "tracker": "SiamFC"})
    assert env.reset(options={"noise_seed": seeds["otb"], "sequence": "Car4"})[1]["track"]["sequence"] == "Car4"


@needs_otb
def test_a_mix_episode_prepared_in_a_block_equals_the_same_episode_pinned() -> None:
    env = _otb(source="mix", track_length=200)
    assert env.unwrapped.source.block > 1
    blocked = [_episode(env, seed=2)] + [_episode(env) for _ in range(7)]
    assert {e[1]["source"] for e in blocked} == set(TRIPLE)
    assert blocked == [_episode(env, _pins(e[1])) for e in blocked]


def test_a_sim_only_mix_needs_no_otb_data(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("OTB_ROOT", raising=False)
    env = gym.make(TUNE, source="mix", mix_weights=(1, 0, 0), track_length=100)
    sim = gym.make(TUNE, source="sim", track_length=100)
    episode = _episode(env, seed=1)
    assert episode[1].pop("source") == "sim" and episode == _episode(sim, seed=1)
    with pytest.raises(ValueError, match="source='mix'.*needs the OTB data.*OTB_ROOT"):
        gym.make(TUNE, source="mix", track_length=100)
