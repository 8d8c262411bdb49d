"""MOT15 identities as the fourth part of ``source="mix"`` (``mix_weights`` (sim, otb, otb_tracker, mot)): the
configurations of before give the same episodes bit for bit, the 4-tuple and its refusals, the part
frequencies, the split rule, and real detections left as they are (no dropout or outliers on the mot part).

Reference hashes (:data:`REFERENCE`): produced with the code of commit 63dca62 (before the mot part existed, and
before the ``bboxtune`` namespace) by running this file's hash functions there as a script: this file as of commit
b337d96 (the same functions, with the old import names; filter outputs in the env hashes rounded as
:func:`env_hash` rounds them here) copied into a worktree of 63dca62::

    git worktree add --detach /tmp/wt-ref 63dca62
    git show b337d96:tests/envs/test_mix_mot.py > /tmp/wt-ref/tests/envs/test_mix_mot.py  # then round as env_hash
    cd /tmp/wt-ref && OTB_ROOT=... PYTHONPATH=. python -m tests.envs.test_mix_mot

They hash the episodes of the OTB copy in ``$OTB_ROOT`` (``shared/data/otb``); another copy of the data gives
other hashes.
"""

from __future__ import annotations

import hashlib
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from bboxtune import envs
from bboxtune.envs.data import mot
from bboxtune.envs.episodes.config import MIX_SOURCES, EnvConfig
from bboxtune.envs.episodes.sources import make_source
from bboxtune.filters import jit
from tests.envs.conftest import OTB_ROOT, needs_otb
from tests.envs.test_vector import _single_steps, _tracks

TUNE, RETUNE = "bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"
FITTED_SIM = {  # docs/results/mot15_noise/fitted_env_kwargs.json, less its source
    "sim_noise": "box", "motion": "otb", "psi_range": (0.2126, 0.7795), "cmn_rel_range": (0.07917, 0.123),
    "detection_dropout": "runs", "miss_rate_range": (0.1724, 0.8483), "miss_run_range": (1.0, 17.14),
    "tau_range": (0.03333, 0.1429), "track_length": 173, "box_size_range": (95.0, 422.0)}
# Existing mix configurations (3-tuples or the default); name -> (needs OTB, EnvConfig kwargs).
OLD_SOURCES: dict[str, tuple[bool, dict[str, Any]]] = {
    "sim_only": (False, {"mix_weights": (1, 0, 0), "track_length": 200}),
    "sim_only_fitted": (False, {"mix_weights": (1.0, 0.0, 0.0), **FITTED_SIM}),
    "sim_only_nonstationary": (False, {"mix_weights": (2, 0, 0), "track_length": 150, "scenario": "nonstationary"}),
    "default": (True, {"track_length": 200}),
    "trackers_speedup_bernoulli": (True, {"mix_weights": (0.5, 0.2, 2.0), "trackers": ("STRUCK", "MDNet"),
                                          "otb_speedup_max": 3, "detection_dropout": "bernoulli", "track_length": 120}),
    "val_no_tracker": (True, {"mix_weights": (1, 3, 0), "split": "val", "track_length": 100}),
    "test_otb_motion_runs": (True, {"split": "test", "otb_speedup_max": 2, "motion": "otb", "detection_dropout": "runs",
                                    "miss_run_range": (1.0, 17.14), "track_length": 173}),
}
OLD_ENVS: dict[str, tuple[bool, str, dict[str, Any]]] = {
    "tune_sim_only": (False, TUNE, {"mix_weights": (1, 0, 0), "track_length": 150}),
    "tune_default": (True, TUNE, {"track_length": 120}),
    "retune_runs": (True, RETUNE, {"mix_weights": (1, 1, 2), "track_length": 120, "window": 30,
                                   "detection_dropout": "runs", "outlier_rate_range": (0.0, 0.2)}),
}
SEEDS = [*range(20), 10**9 + 7, 2 * 10**9 + 3, 2**61 + 11]
# reference_hashes(with_otb=True) at commit 63dca62 (module docstring), OTB_ROOT=shared/data/otb
REFERENCE = {
    "source:sim_only": "98426fceeea92f7b18fc",
    "source:sim_only_fitted": "02f06b6336519dca4377",
    "source:sim_only_nonstationary": "6a4d4bb8a97ff0f77b54",
    "source:default": "0430c0d0776c5f432862",
    "source:trackers_speedup_bernoulli": "1d71b521fab240c00b47",
    "source:val_no_tracker": "c4a96dd480c42058b83a",
    "source:test_otb_motion_runs": "ba61677c5b4d18fe2311",
    "env:tune_sim_only": "eaeb5b44ce19fded673f",
    "env:tune_default": "048af278c4c3201c58cc",
    "env:retune_runs": "a5e7949527fab4a70978",
}
HARSH = {"detection_dropout": "runs", "miss_rate_range": (0.5, 0.95), "miss_run_range": (1.0, 1000.0),
         "outlier_rate_range": (0.3, 0.5)}
SIM_MOT = {"source": "mix", "mix_weights": (1, 0, 0, 1)}


def _digest(parts: list[bytes]) -> str:
    return hashlib.sha256(b"\0".join(parts)).hexdigest()[:20]


def _canon(value: Any) -> str:
    """A stable text of a meta / scenario value (dicts by sorted key)."""
    if isinstance(value, dict):
        return "{" + ",".join(f"{k!r}:{_canon(value[k])}" for k in sorted(value)) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_canon(v) for v in value) + "]"
    if isinstance(value, np.ndarray):
        return f"array{value.dtype}{value.shape}{value.tobytes().hex()}"
    if isinstance(value, (float, np.floating)):
        return float(value).hex()
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(int(value))
    return repr(value)


def episode_bytes(ep: Any) -> bytes:
    """Everything of an episode: boxes (NaN rows included), τ, nominal, meta, scenario."""
    arrays = b"".join(np.ascontiguousarray(a, dtype=np.float64).tobytes() for a in (ep.truth, ep.y))
    return arrays + _canon([ep.tau, vars(ep.nominal), ep.meta, ep.scenario]).encode()


def source_hash(kwargs: dict[str, Any]) -> str:
    """The episodes of :data:`SEEDS` drawn in one batch and one at a time, and three pinned by their meta."""
    cfg = EnvConfig(source="mix", otb_root=OTB_ROOT, **kwargs)
    source = make_source(cfg)
    episodes = source.draw_many(SEEDS) + [source.draw(None, s) for s in SEEDS[:6]]
    for ep in episodes[:8]:
        if ep.meta.get("sequence") is not None:
            pins = {"tracker": ep.meta["tracker"]} if ep.meta.get("tracker") else {}
            episodes.append(source.draw(ep.meta["sequence"], ep.meta["noise_seed"], **pins))
    return _digest([episode_bytes(ep) for ep in episodes])


def _rounded(value: Any, digits: int = 10) -> str:
    """A filter output (reward, score) to 10 significant digits: the rule's last bit depends on the process (the same
    code at 63dca62 gives RMSEs 1 ulp apart depending on what ran before it: numpy's reductions round by alignment)."""
    if isinstance(value, dict):
        return "{" + ",".join(f"{k!r}:{_rounded(value[k], digits)}" for k in sorted(value)) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_rounded(v, digits) for v in value) + "]"
    if isinstance(value, (float, np.floating)):  # below 1e-9: cancellation noise of a zero (e.g. a mean residual)
        return f"{float(value):.{digits - 1}e}" if abs(value) >= 1e-9 else "0"
    return _canon(value)


def env_hash(env_id: str, kwargs: dict[str, Any]) -> str:
    """The episodes (bit for bit) and track infos of 6 episodes (reset(seed=3), then unseeded), their observations
    (to 6 digits, and |x| < 1e-9 as 0: float32 features of filter runs) and their rewards and step infos with fixed
    actions (ufir_cmn; to 10 digits, :func:`_rounded`)."""
    env = gym.make(env_id, source="mix", backend="ufir_cmn", otb_root=OTB_ROOT, **kwargs)
    parts = []
    for i in range(6):
        obs, info = env.reset(seed=3 if i == 0 else None)
        parts += [episode_bytes(env.unwrapped.episode), _rounded(obs.tolist(), 6).encode(), _canon(info).encode()]
        terminated = False
        while not terminated:
            obs, reward, terminated, _, step = env.step(np.full(env.action_space.shape, 0.2 - 0.1 * i, np.float32))
            parts += [_rounded(obs.tolist(), 6).encode(),
                      _rounded([reward, {k: v for k, v in step.items() if k != "params"}]).encode()]
    return _digest(parts)


def reference_hashes(with_otb: bool) -> dict[str, str]:
    """The hashes of every configuration of :data:`OLD_SOURCES` and :data:`OLD_ENVS` (OTB-backed ones with ``with_otb``)."""
    hashes = {f"source:{name}": source_hash(kw) for name, (otb, kw) in OLD_SOURCES.items() if with_otb or not otb}
    hashes.update({f"env:{name}": env_hash(env_id, kw) for name, (otb, env_id, kw) in OLD_ENVS.items()
                   if with_otb or not otb})
    return hashes


def _missing(y: np.ndarray) -> np.ndarray:
    return np.isnan(y).all(axis=-1)


def _same(a: Any, b: Any, *, drop_source: bool = False) -> None:
    """Episodes ``a`` and ``b`` equal bit for bit (NaN rows included); ``drop_source``: ``a``'s meta less its part."""
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.truth, b.truth)
    meta = {k: v for k, v in a.meta.items() if k != "source"} if drop_source else a.meta
    assert (a.tau, a.nominal, meta, a.scenario) == (b.tau, b.nominal, b.meta, b.scenario)


def _episode(env: gym.Env, options: dict | None = None, seed: int | None = None) -> tuple:
    """Everything an agent gets from one FilterTune-v0 episode with a fixed action, comparable with ==."""
    obs, info = env.reset(seed=seed, options=options)
    _, reward, *_, step = env.step(np.full(env.action_space.shape, 0.2, np.float32))
    return obs.tobytes(), info["track"], reward, step["rule_rmse"], step.get("scenario")


# --- the configurations of before ---------------------------------------------------------------------------------
@pytest.mark.parametrize("key", sorted(REFERENCE))
def test_old_mix_configurations_draw_the_same_episodes_bit_for_bit(key: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The hashes were taken on the numpy code: env cases (rewards to 10 digits) run the numpy references, whose
    compiled kernels agree with them to ~1e-12 relative (tests/**/test_*kernels.py), enough to move a 10th digit."""
    kind, name = key.split(":")
    monkeypatch.setattr(jit, "ENABLED", kind == "source")
    needs = OLD_SOURCES[name][0] if kind == "source" else OLD_ENVS[name][0]
    if needs and not OTB_ROOT:
        pytest.skip(reason="OTB_ROOT is unset: OTB-backed env cases need the OTB data")
    got = source_hash(OLD_SOURCES[name][1]) if kind == "source" else env_hash(*OLD_ENVS[name][1:])
    assert got == REFERENCE[key]


# --- configuration --------------------------------------------------------------------------------------------------
def test_mix_weights_take_a_mot_weight_and_keep_the_triple() -> None:
    assert EnvConfig().mix_weights == (1.0, 1.0, 1.0)  # the default as before
    cfg = EnvConfig(source="mix", mix_weights=np.array([1, 0, 0, 2]))
    assert cfg.mix_weights == (1.0, 0.0, 0.0, 2.0)
    assert cfg.mix_parts == {"sim": 1.0, "otb": 0.0, "otb_tracker": 0.0, "mot": 2.0}
    triple = EnvConfig(source="mix", mix_weights=(2, 0, 1))
    assert triple.mix_parts == {"sim": 2.0, "otb": 0.0, "otb_tracker": 1.0, "mot": 0.0}
    assert EnvConfig(source="mix", mix_weights=[2, 0, 1, 0]) == triple  # mot weight 0: the triple, one value
    assert EnvConfig(source="mix", mix_weights=(2, 0, 1, 0)).mix_weights == (2.0, 0.0, 1.0)
    assert EnvConfig(mix_weights=(1, 1, 1, 0)) == EnvConfig()  # the default, written with its mot weight
    assert tuple(EnvConfig(source="mix").mix_parts) == MIX_SOURCES
    assert EnvConfig(source="mix", mix_weights=(0, 0, 0, 1), mot_root="m").mot_root == "m"
    assert EnvConfig(source="mix", mix_weights=(1, 0, 0, 1), **HARSH).detection_dropout == "runs"  # the sim part's


@pytest.mark.parametrize("kwargs, error, match", [
    ({"mix_weights": (1, 1, 1, 1, 1)}, TypeError, r"mix_weights=.*\(sim, otb, otb_tracker, mot\) 4-tuple"),
    ({"mix_weights": (1,)}, TypeError, r"mix_weights=.*\(sim, otb, otb_tracker\) triple"),
    ({"mix_weights": (1, 0, 0, -1)}, ValueError, r"mix_weights\[3\]=-1 is out of range; allowed: a real number in \[0, 1e\+06\]"),
    ({"mix_weights": (1, 0, 0, float("nan"))}, ValueError, r"mix_weights\[3\]"),
    ({"mix_weights": (1, 0, 0, 2e6)}, ValueError, r"mix_weights\[3\]"),
    ({"mix_weights": (1, 0, 0, True)}, TypeError, r"mix_weights\[3\]"),
    ({"mix_weights": (1, 0, 0, "1")}, TypeError, r"mix_weights\[3\]"),
    ({"mix_weights": (0, 0, 0, 0)}, ValueError, "positive sum"),
    ({"source": "mot", "mix_weights": (0, 0, 0, 1)}, ValueError, "mix_weights=.*source='mot': allowed only with source 'mix'"),
    ({"mot_root": "m"}, ValueError, (r"mot_root='m' with source='mix', mix_weights=\(1.0, 1.0, 1.0\): allowed only "
                                     r"with source 'mot', or 'mix' with a positive mot weight \(mix_weights\[3\]\)")),
    ({"mot_root": "m", "mix_weights": (1, 0, 0, 0)}, ValueError, r"mot_root='m' with source='mix'.*mix_weights\[3\]"),
    ({"source": "otb", "mot_root": "m"}, ValueError, r"mot_root='m' with source='otb'"),
    ({"mix_weights": (1, 0, 0, 1), "trackers": ("SiamFC",)}, ValueError, r"trackers=.*mix_weights\[2\]"),
    ({"mix_weights": (0, 0, 0, 1), "detection_dropout": "runs"}, ValueError,
     r"detection_dropout='runs' with source='mix'.*allowed only with .*'mix' with a positive sim, otb or otb_tracker weight"),
    ({"mix_weights": (0, 0, 0, 3), "outlier_rate_range": (0.1, 0.2)}, ValueError,
     r"outlier_rate_range=\(0.1, 0.2\) with source='mix'.*positive sim, otb or otb_tracker weight"),
])
def test_bad_mot_mix_arguments_are_refused_by_name(kwargs: dict, error: type, match: str) -> None:
    kwargs = {"source": "mix", **kwargs}
    with pytest.raises(error, match=match):
        EnvConfig(**kwargs)
    with pytest.raises(error, match=match):
        gym.make(TUNE, **kwargs)


def test_the_mot_part_needs_the_mot_data(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.delenv("MOT_ROOT", raising=False)
    with pytest.raises(ValueError, match=r"source='mix' with mix_weights=\(1.0, 0.0, 0.0, 1.0\) draws MOT episodes and "
                                         r"needs the MOT15 data \(mot_root or \$MOT_ROOT.*MOT_ROOT"):
        gym.make(TUNE, **SIM_MOT)
    with pytest.raises(ValueError, match="draws MOT episodes.*nope"):
        gym.make(TUNE, **SIM_MOT, mot_root=str(tmp_path / "nope"))
    gym.make(TUNE, source="mix", mix_weights=(1, 0, 0, 0))  # weight 0: no MOT data needed


# --- episodes -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("weights", [(1, 0, 0, 1), (0, 0, 0, 1), (3, 0, 0, 1),
                                     pytest.param((1, 1, 1, 1), marks=needs_otb),
                                     pytest.param((0.5, 0.2, 2.0, 3.0), marks=needs_otb)])
def test_mix_draws_each_of_the_four_parts_with_its_weight(weights: tuple, mot_root) -> None:
    source = make_source(EnvConfig(source="mix", mix_weights=weights, mot_root=str(mot_root), otb_root=OTB_ROOT))
    assert set(source.parts) == {part for part, w in zip(MIX_SOURCES, weights, strict=False) if w > 0}
    n = 6000
    counts = np.array([sum(source.part_of(seed) == part for seed in range(n)) for part in MIX_SOURCES])
    p = np.array(weights) / sum(weights)
    assert np.all(np.abs(counts - n * p) <= 4 * np.sqrt(n * p * (1 - p)) + 1e-9)  # 4 binomial std, fixed seeds


def test_a_mix_episode_is_its_parts_episode_with_fitted_sim_and_strides(mot_root) -> None:
    """sim (fitted, with detection errors) + MOT train at strides 1-3: each episode is its part's, bit for bit."""
    kw = {**FITTED_SIM, "mot_root": str(mot_root)}
    mix = make_source(EnvConfig(**SIM_MOT, otb_speedup_max=3, **kw))
    sim = make_source(EnvConfig(source="sim", **FITTED_SIM))
    mot_part = make_source(EnvConfig(source="mot", otb_speedup_max=3, mot_root=str(mot_root)))
    seeds = list(range(40))
    episodes = mix.draw_many(seeds)
    assert [ep.meta["source"] for ep in episodes] == [mix.part_of(s) for s in seeds]
    for seed, ep in zip(seeds, episodes, strict=False):
        part = sim if ep.meta["source"] == "sim" else mot_part
        _same(ep, part.draw(None, seed), drop_source=True)
        _same(ep, mix.draw(ep.meta["sequence"], seed))  # its meta pins it
    strides = {ep.meta.get("stride", 1) for ep in episodes if ep.meta["source"] == "mot"}
    assert {ep.meta["source"] for ep in episodes} == {"sim", "mot"} and strides == {1, 2, 3}


def test_mot_episodes_keep_their_real_gaps_under_detection_errors(mot_root) -> None:
    """Dropout and outliers act on the sim part; a mot episode is MOT15's detection stream, NaN gaps as they are."""
    plain = make_source(EnvConfig(**SIM_MOT, mot_root=str(mot_root), track_length=200))
    harsh = make_source(EnvConfig(**SIM_MOT, mot_root=str(mot_root), track_length=200, **HARSH))
    seeds = list(range(60))
    gaps = missed = 0
    for a, b in zip(plain.draw_many(seeds), harsh.draw_many(seeds), strict=False):
        if a.meta["source"] == "mot":
            _same(b, a)  # y with its NaN rows, truth, nominal, meta, scenario (no miss_rate / outlier_rate drawn)
            assert b.scenario == {} and np.isfinite(b.y[[0, -1]]).all()
            gaps += int(_missing(b.y).sum())
        else:
            assert {"miss_rate", "miss_run", "outlier_rate"} <= b.scenario.keys()
            missed += int((_missing(b.y) & ~_missing(a.y)).sum())
    assert gaps > 0 and missed > 0  # the real streams have gaps; the sim part's errors are on


@pytest.mark.parametrize("split", ["train", "val", "test"])
def test_the_mot_part_draws_its_splits_identities(split: str, mot_root) -> None:
    source = make_source(EnvConfig(source="mix", mix_weights=(1, 0, 0, 3), split=split, otb_speedup_max=3,
                                   mot_root=str(mot_root)))
    pool = {f"{i.sequence}/{i.identity}" for i in mot.split(mot.load_identities(mot_root))[split]}
    assert set(source.parts["mot"].sequences) == pool
    drawn = [ep for ep in source.draw_many(list(range(200))) if ep.meta["source"] == "mot"]
    assert drawn and {ep.meta["sequence"] for ep in drawn} <= pool
    sequences = {name.split("/")[0] for name in pool}
    assert sequences == {"train": {"ETH-Pedcross2", "Venice-2"}, "val": {"ADL-Rundle-6", "ADL-Rundle-8", "ETH-Bahnhof"},
                         "test": {"KITTI-13"}}[split]
    assert any("stride" in ep.meta for ep in drawn) == (split == "train")  # strides on the train split only


@pytest.mark.parametrize("env_id", [TUNE, RETUNE])
def test_env_reports_mot_episodes_and_pins_them(env_id: str, mot_root) -> None:
    env = gym.make(env_id, **SIM_MOT, mot_root=str(mot_root), track_length=200, backend="ufir_cmn")
    parts = {"sim": gym.make(env_id, source="sim", track_length=200, backend="ufir_cmn"),
             "mot": gym.make(env_id, source="mot", mot_root=str(mot_root), backend="ufir_cmn")}
    source = env.unwrapped.source
    seeds = {part: next(s for s in range(100) if source.part_of(s) == part) for part in parts}
    for part, seed in seeds.items():
        _, info = env.reset(options={"noise_seed": seed})
        assert info["track"]["source"] == part
        if env_id == TUNE:
            episode = _episode(env, {"noise_seed": seed})
            assert episode[1].pop("source") == part and episode == _episode(parts[part], {"noise_seed": seed})
    _, info = env.reset(options={"noise_seed": seeds["mot"]})
    name = info["track"]["sequence"]
    other = next(n for n in source.parts["mot"].sequences if n != name)
    assert env.reset(options={"noise_seed": seeds["mot"], "sequence": other})[1]["track"]["sequence"] == other
    with pytest.raises(ValueError, match=r"options\['sequence'\]='Venice-2/1': noise_seed=\d+ draws a 'sim' episode.*'mot'"):
        env.reset(options={"noise_seed": seeds["sim"], "sequence": "Venice-2/1"})
    with pytest.raises(ValueError, match=r"options\['sequence'\]='KITTI-13/7' is not a MOT identity of split 'train'"):
        env.reset(options={"noise_seed": seeds["mot"], "sequence": "KITTI-13/7"})
    with pytest.raises(ValueError, match=r"options\['tracker'\].*no trackers"):
        env.reset(options={"noise_seed": seeds["mot"], "tracker": "SiamFC"})


def test_the_batched_env_draws_the_single_envs_mot_mix_episodes(mot_root) -> None:
    kwargs = {"backend": "ufir_cmn", **SIM_MOT, "mot_root": str(mot_root), "otb_speedup_max": 3, **FITTED_SIM}
    venv = envs.make_vec(TUNE, 8, **kwargs)
    obs, infos = venv.reset(seed=5)
    tracks = _tracks(infos, 8)
    assert {t["source"] for t in tracks} == {"sim", "mot"}
    actions = np.random.default_rng(1).uniform(-1, 1, (8, 2)).astype(np.float32)
    _, rewards, *_ = venv.step(actions)
    single_obs, single_rewards, _ = _single_steps(kwargs, tracks, actions)
    np.testing.assert_allclose(obs, single_obs, rtol=1e-6)
    np.testing.assert_allclose(rewards, single_rewards, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn"])
@pytest.mark.parametrize("env_id", [TUNE, RETUNE])
def test_checkers_pass_on_a_mot_mix(env_id: str, backend: str, mot_root) -> None:
    env = gym.make(env_id, backend=backend, **SIM_MOT, mot_root=str(mot_root), otb_speedup_max=2, track_length=120,
                   window=30, detection_dropout="runs")
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)


def test_old_mix_with_sim_noise_box_or_nonstationary_and_otb_weight_is_drawn() -> None:
    """Refused before by the OTB parts' own configs: the sim part's settings now go to the sim part only."""
    if not OTB_ROOT:
        pytest.skip(reason="OTB_ROOT is unset: OTB-backed env cases need the OTB data")
    for extra in ({"sim_noise": "box"}, {"scenario": "nonstationary"}):
        mix = make_source(EnvConfig(source="mix", otb_root=OTB_ROOT, track_length=150, **extra))
        sim = make_source(EnvConfig(source="sim", track_length=150, **extra))
        otb = make_source(EnvConfig(source="otb", otb_root=OTB_ROOT))
        for seed, ep in enumerate(mix.draw_many(list(range(12)))):
            if ep.meta["source"] in ("sim", "otb"):
                _same(ep, (sim if ep.meta["source"] == "sim" else otb).draw(None, seed), drop_source=True)


if __name__ == "__main__":
    for key, value in reference_hashes(with_otb=bool(OTB_ROOT)).items():
        print(f"    {key!r}: {value!r},")
