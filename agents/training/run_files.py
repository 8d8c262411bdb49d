"""Data files of a run directory, read and written without pickle: VecNormalize statistics as JSON, replay
buffers as ``.npz``, atomic writes, and the error every unusable file raises (:class:`RunError`).

Statistics file (``vecnormalize.json``, ``best_vecnormalize.json``, ``checkpoints/ckpt_*/vecnormalize.json``)::

    {"format": "bboxtune-vecnormalize-1", "norm_obs": true, "norm_reward": false, "clip_obs": 10.0,
     "clip_reward": 10.0, "gamma": 0.99, "epsilon": 1e-08,
     "obs_rms": {"mean": [...], "var": [...], "count": 2048.0}, "ret_rms": {"mean": 0.0, "var": 1.0, "count": 0.0001}}

``obs_rms`` / ``ret_rms`` are SB3's ``RunningMeanStd`` of the observations (one entry per observation
component) and of the discounted return; floats are written with Python's ``repr``, so they read back bit for
bit. SB3's own format (``VecNormalize.save``, a pickle) can run arbitrary code when loaded: a ``*.pkl`` file is
read only when the caller passes ``trust_pickle=True`` (the scripts' ``--trust-pickle``), and is then
converted to the JSON file beside it. Replay buffers (off-policy checkpoints) are ``replay_buffer.npz``,
read with ``allow_pickle=False``.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

if TYPE_CHECKING:
    from stable_baselines3.common.buffers import ReplayBuffer
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
    from stable_baselines3.common.running_mean_std import RunningMeanStd

from bboxtune.agents import readers
from bboxtune.agents.readers import json_number, json_vector
from bboxtune.envs.data import textfile
from bboxtune.envs.data.atomic_files import atomic_write_file, write_text_atomic

STATS_FORMAT = "bboxtune-vecnormalize-1"
STATS = "vecnormalize.json"
PICKLED_STATS = "vecnormalize.pkl"
OBS_SIZE = "the observation size"
REPLAY = "replay_buffer.npz"
PICKLED_REPLAY = "replay_buffer.pkl"
_REPLAY_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


class RunError(ValueError):
    """A run directory, one of its files or a setting given for it is unusable; the message names the file."""


def read_json(path: Path) -> Any:
    """A JSON document (``NaN``/``Infinity`` refused, bounded read); :class:`RunError` naming ``path`` (and line)."""
    try:
        return readers.read_json(Path(path))
    except ValueError as err:
        raise RunError(str(err)) from None


def save_stats(venv: VecNormalize, path: Path) -> None:
    """Write ``venv``'s statistics and settings to the JSON file ``path`` (atomically)."""
    if isinstance(venv.obs_rms, dict):
        raise RunError("VecNormalize of a Dict observation space: not supported by the statistics file")
    obs, ret = venv.obs_rms, venv.ret_rms
    doc = {"format": STATS_FORMAT, "norm_obs": bool(venv.norm_obs), "norm_reward": bool(venv.norm_reward),
           "clip_obs": float(venv.clip_obs), "clip_reward": float(venv.clip_reward), "gamma": float(venv.gamma),
           "epsilon": float(venv.epsilon),
           "obs_rms": {"mean": obs.mean.tolist(), "var": obs.var.tolist(), "count": float(obs.count)},
           "ret_rms": {"mean": float(ret.mean), "var": float(ret.var), "count": float(ret.count)}}
    write_text_atomic(path, json.dumps(doc, indent=1) + "\n")


def load_stats(path: Path, venv: VecEnv, *, training: bool) -> VecNormalize:
    """``venv`` wrapped in a VecNormalize holding the statistics of the JSON file ``path``; :class:`RunError`
    naming the file if it is malformed or does not fit ``venv``'s observations."""
    path = Path(path)
    doc = read_json(path)
    if not isinstance(doc, dict) or doc.get("format") != STATS_FORMAT:
        raise RunError(f"{path}: not a statistics file (expected a JSON object with format {STATS_FORMAT!r})")
    flags = {k: doc.get(k) for k in ("norm_obs", "norm_reward")}
    if not all(isinstance(v, bool) for v in flags.values()):
        raise RunError(f"{path}: norm_obs and norm_reward must be true or false, got {flags}")
    shape = venv.observation_space.shape
    if shape is None or len(shape) != 1:
        raise RunError(f"{path}: statistics of a flat Box observation expected; the env's observation is "
                       f"{venv.observation_space}")
    obs, ret = doc.get("obs_rms"), doc.get("ret_rms")
    if not isinstance(obs, dict) or not isinstance(ret, dict):
        raise RunError(f"{path}: obs_rms and ret_rms must be objects with mean, var, count")
    settings = {k: json_number(doc, k, path, 0.0, RunError) for k in ("clip_obs", "clip_reward", "gamma", "epsilon")}
    norm = VecNormalize(venv, training=training, norm_obs=cast(bool, flags["norm_obs"]),
                        norm_reward=cast(bool, flags["norm_reward"]), clip_obs=settings["clip_obs"],
                        clip_reward=settings["clip_reward"], gamma=settings["gamma"], epsilon=settings["epsilon"])
    obs_rms = cast("RunningMeanStd", norm.obs_rms)  # one RunningMeanStd: a flat Box observation (checked above)
    obs_rms.mean = json_vector(obs, "mean", shape[0], path, what=OBS_SIZE, error=RunError)
    obs_rms.var = json_vector(obs, "var", shape[0], path, 0.0, OBS_SIZE, RunError)
    obs_rms.count = json_number(obs, "count", path, 0.0, RunError)
    norm.ret_rms.mean = np.float64(json_number(ret, "mean", path, error=RunError))
    norm.ret_rms.var = np.float64(json_number(ret, "var", path, 0.0, RunError))
    norm.ret_rms.count = json_number(ret, "count", path, 0.0, RunError)
    return norm


def load_normalizer(folder: Path, venv: VecEnv, *, prefix: str = "", training: bool = False,
                    trust_pickle: bool = False) -> VecNormalize | None:
    """The statistics ``<folder>/<prefix>vecnormalize.json`` around ``venv`` (None if the folder has none).

    An old run with only ``<prefix>vecnormalize.pkl`` is refused (:class:`RunError`) unless ``trust_pickle``;
    with it the pickle is loaded and converted to the JSON file (reported on stdout)."""
    folder = Path(folder)
    path, pickled = folder / (prefix + STATS), folder / (prefix + PICKLED_STATS)
    if path.exists():
        return load_stats(path, venv, training=training)
    if not pickled.exists():
        return None
    if not trust_pickle:
        raise RunError(f"{pickled}: statistics stored as a pickle, which can run code when loaded; pass --trust-pickle "
                       f"only if you trust where this run comes from (it is then converted to {path.name})")
    try:
        norm = VecNormalize.load(str(pickled), venv)  # the caller has vouched for this file
    except Exception as err:  # noqa: BLE001  (an untrusted-format file: any failure is this file's)
        raise RunError(f"{pickled}: cannot be loaded ({type(err).__name__}: {err})") from None
    norm.training = training
    try:
        save_stats(norm, path)
        print(f"converted {pickled} to {path}")
    except OSError as err:
        print(f"could not write {path} ({err}); the pickle will be needed again next time")
    return norm


def _replay_buffer(model: BaseAlgorithm) -> ReplayBuffer:
    """``model.replay_buffer``, typed: the callers check that the (off-policy) model has one."""
    return cast("ReplayBuffer", cast("OffPolicyAlgorithm", model).replay_buffer)


def save_replay_buffer(model: BaseAlgorithm, path: Path) -> None:
    """The replay buffer of an off-policy ``model`` as ``.npz`` (arrays, ``pos``, ``full``)."""
    rb = _replay_buffer(model)
    arrays = {k: getattr(rb, k) for k in _REPLAY_ARRAYS if getattr(rb, k, None) is not None}

    atomic_write_file(path, lambda fh: np.savez(fh, pos=np.int64(rb.pos), full=np.bool_(rb.full), **arrays))


def load_replay_buffer(model: BaseAlgorithm, path: Path) -> None:
    """Fill ``model.replay_buffer`` from :func:`save_replay_buffer`'s file; :class:`RunError` naming ``path`` if
    it is unreadable or its arrays do not match the buffer's shapes and dtypes."""
    rb = _replay_buffer(model)
    wanted = {k for k in _REPLAY_ARRAYS if getattr(rb, k, None) is not None} | {"pos", "full"}
    try:
        textfile.check_regular(path)
        with np.load(path, allow_pickle=False) as data:
            files = set(data.files)
            loaded = {k: data[k] for k in wanted & files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise RunError(f"{path}: not a readable replay buffer ({err})") from None
    if files != wanted:
        raise RunError(f"{path}: arrays {sorted(files)}; expected {sorted(wanted)}")
    for key in wanted - {"pos", "full"}:
        have = getattr(rb, key)
        if loaded[key].shape != have.shape or loaded[key].dtype != have.dtype:
            raise RunError(f"{path}: {key} has shape {loaded[key].shape} {loaded[key].dtype}; the model's buffer "
                           f"needs {have.shape} {have.dtype}")
    pos, full = loaded["pos"], loaded["full"]
    if pos.shape != () or not 0 <= int(pos) < rb.buffer_size or full.shape != () or full.dtype != np.bool_:
        raise RunError(f"{path}: pos={pos!r}, full={full!r}; expected 0 <= pos < {rb.buffer_size} and a boolean")
    for key in wanted - {"pos", "full"}:
        getattr(rb, key)[...] = loaded[key]
    rb.pos, rb.full = int(pos), bool(full)
