"""Run files are read without unpickling: planted pickles in model.zip (every serialized data entry, the weight
files), statistics and replay buffers never run; statistics round-trip bit for bit; mismatches are named.

Every plant has a positive control: the naive reader (SB3's ``load``, ``VecNormalize.load``, ``torch.load``,
``np.load(allow_pickle=True)``) does run it, so the marker file shows that the plant is live.
"""

from __future__ import annotations

import base64
import io
import json
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from bboxtune.agents.training.algos import ALGOS, algo_class
from bboxtune.agents.training.hyperparams import constructor_kwargs, load_hyperparams
from bboxtune.agents.training.run_files import (
    RunError,
    load_normalizer,
    load_replay_buffer,
    load_stats,
    save_replay_buffer,
    save_stats,
)
from bboxtune.agents.training.runs import make_vec
from bboxtune.agents.training.safe_load import check_env_match, load_model, stamp

from ..conftest import ENV_ID, SHORT

SMALL = {"ppo": {"n_steps": 16, "batch_size": 16}, "ppo_lstm": {"n_steps": 16, "batch_size": 16}, "a2c": {"n_steps": 8},
         "sac": {"buffer_size": 256}, "td3": {"buffer_size": 256}}


class Plant:
    """Unpickles to ``open(marker, "w")``: creates the marker file (harmless, but it is code from the file)."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self) -> tuple[Any, ...]:
        return (open, (self.marker, "w"))


def naive(load: Any, *args: Any, **kwargs: Any) -> None:
    """Positive control: the naive reader on a planted file (it runs the plant, then may fail on what it got)."""
    try:
        load(*args, **kwargs)
    except Exception:  # noqa: BLE001  (only whether the plant ran matters)
        pass


def payload(marker: Path) -> str:
    return base64.b64encode(pickle.dumps(Plant(marker))).decode()


def config(algo: str, backend: str = "ufir_cmn") -> dict[str, Any]:
    hp = load_hyperparams(algo, ENV_ID, {**SMALL[algo], "n_envs": 1})
    return {"algo": algo, "env_id": ENV_ID, "env_kwargs": {"backend": backend, **SHORT}, "hyperparams": hp.raw, "seed": 0}


def venv_of(cfg: dict[str, Any]) -> DummyVecEnv:
    return make_vec(cfg["env_id"], cfg["env_kwargs"], split="train", n_envs=1, seed=0)


def saved_model(tmp_path: Path, cfg: dict[str, Any], name: str = "model.zip") -> Path:
    hp = load_hyperparams(cfg["algo"], cfg["env_id"], cfg["hyperparams"])
    venv = venv_of(cfg)
    model = algo_class(cfg["algo"])(hp.policy, venv, seed=0, device="cpu", **constructor_kwargs(hp, venv.action_space.shape[0]))
    stamp(model, cfg)
    model.save(tmp_path / name)
    return tmp_path / name


def rewrite_zip(path: Path, change: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path) as archive:
        members = {n: archive.read(n) for n in archive.namelist()}
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in {**members, **change}.items():
            archive.writestr(name, data)


def zip_data(path: Path) -> dict[str, Any]:
    with zipfile.ZipFile(path) as archive:
        return json.loads(archive.read("data"))


def serialized_keys(data: dict[str, Any]) -> list[str]:
    return [k for k, v in data.items() if isinstance(v, dict) and ":serialized:" in v]


@pytest.mark.parametrize("algo", sorted(ALGOS))
def test_no_serialized_entry_of_model_zip_is_unpickled(algo: str, tmp_path: Path) -> None:
    cfg = config(algo)
    path = saved_model(tmp_path, cfg)
    data = zip_data(path)
    keys = serialized_keys(data)
    assert {"policy_class", "observation_space", "action_space", "lr_schedule"} <= set(keys)
    marker = tmp_path / "ran"
    for key in keys:  # every pickled entry now runs code when unpickled
        data[key][":serialized:"] = payload(marker)
    rewrite_zip(path, {"data": json.dumps(data).encode()})
    model = load_model(path, cfg, venv_of(cfg))
    assert not marker.exists()
    assert model.observation_space.shape == (20,) and model.action_space.shape == (2,)
    policy = load_hyperparams(algo, ENV_ID).policy  # MlpPolicy; MlpLstmPolicy for ppo_lstm
    assert type(model.policy).__name__ == type(algo_class(algo)(policy, venv_of(cfg), device="cpu").policy).__name__
    naive(algo_class(algo).load, path, device="cpu")  # positive control: SB3's own loader runs the plant
    assert marker.exists()


def test_a_pickled_entry_that_cannot_be_rebuilt_is_refused(tmp_path: Path) -> None:
    cfg = config("ppo")
    path = saved_model(tmp_path, cfg)
    data = zip_data(path)
    marker = tmp_path / "ran"
    data["extra_object"] = {":type:": "<class 'object'>", ":serialized:": payload(marker)}
    rewrite_zip(path, {"data": json.dumps(data).encode()})
    with pytest.raises(RunError, match=r"model\.zip: data entries \['extra_object'\] .* refusing to unpickle"):
        load_model(path, cfg, venv_of(cfg))
    assert not marker.exists()
    naive(algo_class("ppo").load, path, device="cpu")  # positive control
    assert marker.exists()


@pytest.mark.parametrize("member", ["policy.pth", "pytorch_variables.pth", "policy.optimizer.pth"])
def test_the_installed_sb3_reads_weights_with_weights_only(member: str, tmp_path: Path) -> None:
    cfg = config("ppo")
    path = saved_model(tmp_path, cfg)
    marker = tmp_path / "ran"
    buffer = io.BytesIO()
    torch.save(Plant(marker), buffer)
    rewrite_zip(path, {member: buffer.getvalue()})
    with pytest.raises(RunError, match=rf"{path}: cannot be loaded"):
        load_model(path, cfg, venv_of(cfg))
    assert not marker.exists()
    naive(torch.load, io.BytesIO(buffer.getvalue()), weights_only=False)  # positive control
    assert marker.exists()


def test_statistics_pickle_is_refused_without_trust(tmp_path: Path) -> None:
    cfg = config("ppo")
    marker = tmp_path / "ran"
    (tmp_path / "vecnormalize.pkl").write_bytes(pickle.dumps(Plant(marker)))
    with pytest.raises(RunError, match=r"vecnormalize\.pkl: .*pickle.*--trust-pickle"):
        load_normalizer(tmp_path, venv_of(cfg))
    assert not marker.exists()
    naive(VecNormalize.load, str(tmp_path / "vecnormalize.pkl"), venv_of(cfg))  # positive control
    assert marker.exists()


def test_trusted_statistics_pickle_is_converted_to_json(tmp_path: Path) -> None:
    cfg = config("ppo")
    norm = VecNormalize(venv_of(cfg))
    norm.obs_rms.mean = np.linspace(-1, 1, 20)
    norm.save(str(tmp_path / "vecnormalize.pkl"))
    loaded = load_normalizer(tmp_path, venv_of(cfg), trust_pickle=True)
    assert (tmp_path / "vecnormalize.json").is_file()
    np.testing.assert_array_equal(loaded.obs_rms.mean, norm.obs_rms.mean)
    (tmp_path / "vecnormalize.pkl").write_bytes(b"not a pickle any more")  # the JSON is used from now on
    np.testing.assert_array_equal(load_normalizer(tmp_path, venv_of(cfg)).obs_rms.mean, norm.obs_rms.mean)


def test_statistics_round_trip_bit_for_bit(tmp_path: Path) -> None:
    cfg = config("ppo")
    rng = np.random.default_rng(0)
    norm = VecNormalize(venv_of(cfg), clip_obs=7.5, gamma=0.97, epsilon=1e-7)
    norm.obs_rms.mean, norm.obs_rms.var, norm.obs_rms.count = rng.normal(size=20), rng.gamma(1.0, size=20), 1234.5
    norm.ret_rms.mean, norm.ret_rms.var = np.float64(0.3), np.float64(2.0)
    save_stats(norm, tmp_path / "s.json")
    back = load_stats(tmp_path / "s.json", venv_of(cfg), training=False)
    for a, b in ((back.obs_rms, norm.obs_rms), (back.ret_rms, norm.ret_rms)):
        np.testing.assert_array_equal(a.mean, b.mean)
        np.testing.assert_array_equal(a.var, b.var)
        assert a.count == b.count
    assert (back.clip_obs, back.gamma, back.epsilon, back.norm_obs, back.norm_reward) == (7.5, 0.97, 1e-7, True, True)
    obs = rng.normal(size=(3, 20)).astype(np.float32)
    np.testing.assert_array_equal(back.normalize_obs(obs), norm.normalize_obs(obs))


@pytest.mark.parametrize(("edit", "message"), [
    (lambda text: text[: len(text) // 2], r"s\.json:\d+:\d+: invalid JSON"),
    (lambda text: text.replace('"var": [', '"var": [-1.0, '), r"s\.json: var must be a list of 20"),
    (lambda text: text.replace('"clip_obs": 10.0', '"clip_obs": NaN'), r"s\.json: invalid JSON: non-standard JSON constant NaN"),
    (lambda text: text.replace('"format"', '"formats"'), r"s\.json: not a statistics file"),
])
def test_malformed_statistics_name_the_file(edit, message: str, tmp_path: Path) -> None:
    cfg = config("ppo")
    save_stats(VecNormalize(venv_of(cfg)), tmp_path / "s.json")
    (tmp_path / "s.json").write_text(edit((tmp_path / "s.json").read_text()))
    with pytest.raises(RunError, match=message):
        load_stats(tmp_path / "s.json", venv_of(cfg), training=False)


def test_statistics_of_another_observation_size_are_refused(tmp_path: Path) -> None:
    save_stats(VecNormalize(DummyVecEnv([lambda: __import__("gymnasium").make("Pendulum-v1")])), tmp_path / "s.json")
    with pytest.raises(RunError, match="list of 20 finite numbers"):
        load_stats(tmp_path / "s.json", venv_of(config("ppo")), training=False)


def test_replay_buffer_round_trip_and_no_object_arrays(tmp_path: Path) -> None:
    cfg = config("sac")
    model = load_model(saved_model(tmp_path, cfg), cfg, venv_of(cfg))
    rb = model.replay_buffer
    rb.observations[:] = np.random.default_rng(1).normal(size=rb.observations.shape)
    rb.pos, rb.full = 17, True
    save_replay_buffer(model, tmp_path / "rb.npz")
    other = load_model(tmp_path / "model.zip", cfg, venv_of(cfg))
    load_replay_buffer(other, tmp_path / "rb.npz")
    np.testing.assert_array_equal(other.replay_buffer.observations, rb.observations)
    assert (other.replay_buffer.pos, other.replay_buffer.full) == (17, True)
    marker = tmp_path / "ran"
    planted = np.empty(1, dtype=object)
    planted[0] = Plant(marker)
    with np.load(tmp_path / "rb.npz") as data:
        arrays = dict(data)
    np.savez(tmp_path / "bad.npz", **{**arrays, "observations": planted})
    with pytest.raises(RunError, match=r"bad\.npz: not a readable replay buffer"):
        load_replay_buffer(other, tmp_path / "bad.npz")
    assert not marker.exists()
    naive(lambda: np.load(tmp_path / "bad.npz", allow_pickle=True)["observations"])  # positive control
    assert marker.exists()


def test_a_model_of_another_env_is_refused(tmp_path: Path) -> None:
    kf_cmn = saved_model(tmp_path, config("ppo", "kf_cmn"), "kf_cmn.zip")  # 3 actions
    with pytest.raises(RunError, match=r"kf_cmn\.zip: action_space float32\[3\] differs from the config's env"):
        load_model(kf_cmn, config("ppo"), venv_of(config("ppo")))
    kf = saved_model(tmp_path, config("ppo", "kf"), "kf.zip")  # 2 actions, as ufir_cmn: only the stamp tells
    with pytest.raises(RunError, match=r"kf\.zip was trained on .*'backend': 'kf'.* but config\.yml says .*ufir_cmn"):
        load_model(kf, config("ppo"), venv_of(config("ppo")))


def test_a_model_of_another_architecture_is_refused(tmp_path: Path) -> None:
    path = saved_model(tmp_path, config("ppo"))
    cfg = config("ppo")
    cfg["hyperparams"] = {**cfg["hyperparams"], "policy_kwargs": {"net_arch": [8], "log_std_init": -1.0}}
    with pytest.raises(RunError, match=r"model\.zip: cannot be loaded as the ppo model config\.yml describes"):
        load_model(path, cfg, venv_of(cfg))


def test_truncated_model_zip_is_named(tmp_path: Path) -> None:
    path = saved_model(tmp_path, config("ppo"))
    path.write_bytes(path.read_bytes()[:5000])
    with pytest.raises(RunError, match=rf"{path}: not a readable zip archive"):
        load_model(path, config("ppo"), venv_of(config("ppo")))


def test_a_model_is_checked_against_the_env_it_is_to_act_in(tmp_path: Path) -> None:
    import gymnasium as gym

    cfg = config("ppo")
    model = load_model(saved_model(tmp_path, cfg), cfg, venv_of(cfg))
    path = tmp_path / "model.zip"
    check_env_match(path, model, cfg, gym.make(ENV_ID, backend="ufir_cmn", source="sim", track_length=60))  # transfer: ok
    with pytest.raises(RunError, match=r"action_space float32\[2\] of the model differs from the evaluation env's "
                                       r"float32\[3\]"):
        check_env_match(path, model, cfg, gym.make(ENV_ID, backend="kf_cmn", **SHORT))
    with pytest.raises(RunError, match=r"action_space float32\[2\] sets \['psi', 'horizon'\] of back end ufir_cmn .* "
                                       r"float32\[2\] sets \['sigma_w', 'sigma_v'\] of back end kf"):
        check_env_match(path, model, cfg, gym.make(ENV_ID, backend="kf", **SHORT))
    with pytest.raises(RunError, match=r"sigma_decades 1\.5\) in its run, but .*sigma_decades 2\)"):
        check_env_match(path, model, {**cfg, "env_kwargs": {**cfg["env_kwargs"], "backend": "oufir"}},
                        gym.make(ENV_ID, backend="oufir", sigma_decades=2.0, **SHORT))
    model.observation_space = gym.spaces.Box(-1.0, 1.0, (5,), np.float32)  # a model of another feature set
    with pytest.raises(RunError, match=r"observation_space float32\[5\] of the model differs from the evaluation "
                                       r"env's float32\[[0-9]+\]"):
        check_env_match(path, model, cfg, gym.make(ENV_ID, **SHORT))
