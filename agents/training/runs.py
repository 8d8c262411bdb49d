"""Training-run directories: their config, the run lock, vectorised envs of a split, and loading a trained tuner.

A run directory written by ``scripts/train.py`` holds only data files (nothing in it is unpickled or run)::

    config.yml            every setting of the run (arguments, env kwargs, hyperparameters, versions); never
                          rewritten after the run starts (a resume appends its command line to command.txt)
    command.txt           the command line that started it (and each resume, appended)
    train.lock            the run lock (:class:`RunLock`), held by the train.py process writing the run
    model.zip             the final model;          vecnormalize.json       its VecNormalize statistics
    best_model.zip        best on the val split;    best_vecnormalize.json  the statistics at that time
    evaluations.npz       EvalCallback log (val split); eval_curve.csv the same as text
    train_log.csv         reward of every training episode;   learning_curve.png
    checkpoints/latest    name of the newest checkpoint folder, checkpoints/ckpt_<timesteps>/
    (bboxtune.agents.training.checkpoints)

Models are loaded by :func:`bboxtune.agents.training.safe_load.load_model` (no unpickling), statistics by
:func:`bboxtune.agents.training.run_files.load_normalizer` (JSON; an old run's ``vecnormalize.pkl`` only with ``trust_pickle``).
The model, statistics, checkpoints, config, logs and curves CSV are written atomically (temporary file or folder,
then ``os.replace``); ``evaluations.npz`` (SB3's EvalCallback) and the PNG are written in place and are never
read back.
"""

from __future__ import annotations

import fcntl
import os
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

from bboxtune import envs  # noqa: F401  (registers the env ids)
from bboxtune.agents.policies.baselines import ObsPolicy
from bboxtune.agents.readers import read_yaml
from bboxtune.agents.splits import SplitSeeds, train_seeds
from bboxtune.agents.training.algos import ALGOS, RECURRENT
from bboxtune.agents.training.batched import TuneVecEnv
from bboxtune.agents.training.deterministic import deterministic_actions
from bboxtune.agents.training.hyperparams import load_hyperparams
from bboxtune.agents.training.obs_normalization import ObsNormalization
from bboxtune.agents.training.run_files import RunError, load_normalizer
from bboxtune.agents.training.safe_load import load_model
from bboxtune.envs import RETUNE_ID
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.features import FEATURE_NAMES, feature_names
from bboxtune.envs.retune_env import retune_observation_names
from bboxtune.envs.vector import BATCHED_IDS, TuneBatch

if TYPE_CHECKING:
    from stable_baselines3.common.running_mean_std import RunningMeanStd

CONFIG = "config.yml"
LOCK = "train.lock"
MODEL_KEYS = {"algo": str, "env_id": str, "env_kwargs": dict, "hyperparams": dict, "seed": int}
RESUME_KEYS = {**MODEL_KEYS, "total_timesteps": int, "eval_freq": int, "eval_episodes": int, "checkpoint_freq": int,
               "tensorboard": bool}
ENV_ERRORS = (gym.error.Error, ValueError, TypeError, KeyError, OSError)  # what a bad env id / env kwargs raise
# a feature whose VecNormalize variance, net of the running statistics' prior, is below this did not vary in
# training; the smallest real one in the shipped tuners (acf3_d2_pos) is ~3e-3
CONSTANT_FEATURE_VAR = 1e-6
# SB3's RunningMeanStd starts from mean 0, var 1 with this count (its epsilon), so a feature constant at c ends with
# var ≈ PRIOR_COUNT · (1 + c²) / count: 4e-8 for log_n_frames of 500-frame tracks after 1e5 steps, 3e-5 after 64
PRIOR_COUNT = 1e-4


def make_env(env_id: str, env_kwargs: dict[str, Any], split: str = "test") -> gym.Env:
    """One env of ``env_id`` whose resets are pinned to ``split`` (:class:`bboxtune.agents.splits.SplitSeeds`; the
    env's own ``split=`` picks the OTB sequences)."""
    return SplitSeeds(gym.make(env_id, **{**env_kwargs, "split": split}), split=split)


def make_vec(env_id: str, env_kwargs: dict[str, Any], *, split: str, n_envs: int, seed: int,
             vec_env: str = "dummy", cycle: int = 100) -> VecEnv:
    """``n_envs`` envs of ``split`` (noise seeds of that split, the env's ``split=`` for OTB sequences):
    ``vec_env="batched"`` (train split of FilterTune-v0 only) one :class:`bboxtune.agents.training.batched.TuneVecEnv` seeded
    with ``seed`` (its infos carry Monitor's ``episode``); ``"dummy"`` / ``"subproc"`` Monitor-wrapped envs with reset seeds
    ``seed + rank`` in a Dummy- or SubprocVecEnv."""
    kwargs = {**env_kwargs, "split": split}
    if vec_env == "batched":
        if split != "train" or env_id not in BATCHED_IDS:
            raise ValueError(f"vec_env='batched' serves the train split of {BATCHED_IDS}, not split={split!r} of {env_id!r}")
        return TuneVecEnv(TuneBatch(n_envs, train_seeds, **kwargs), seed=seed)
    cls = SubprocVecEnv if vec_env == "subproc" else DummyVecEnv
    return make_vec_env(partial(_registered_make, env_id), n_envs=n_envs, seed=seed, env_kwargs=kwargs, vec_env_cls=cls,
                        wrapper_class=SplitSeeds, wrapper_kwargs={"split": split, "cycle": cycle})


def _registered_make(env_id: str, **kwargs: Any) -> gym.Env:
    """``gym.make`` in a SubprocVecEnv worker: unpickling this function imports this module, whose ``import envs``
    registers the env ids there."""
    return gym.make(env_id, **kwargs)


def load_config(run_dir: Path, keys: dict[str, type] = MODEL_KEYS) -> dict[str, Any]:
    """``run_dir/config.yml``, checked to hold ``keys`` with their types (counts >= 1, a known algorithm);
    :class:`RunError` naming the file (and line, for YAML errors) otherwise."""
    run_dir = Path(run_dir)
    path = run_dir / CONFIG
    if not run_dir.is_dir():
        raise RunError(f"{run_dir} is not a folder" if run_dir.exists() else f"{run_dir} does not exist")
    if not path.is_file():
        raise RunError(f"{run_dir} is not a train.py run directory: no {CONFIG}")
    try:
        cfg = read_yaml(path)
    except ValueError as err:
        raise RunError(str(err)) from None
    if not isinstance(cfg, dict):
        raise RunError(f"{path}: expected a mapping of settings, got {type(cfg).__name__}")
    for key, kind in keys.items():
        value = cfg.get(key)
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise RunError(f"{path}: {key}={value!r}; expected a {kind.__name__}")
        if kind is int and key != "seed" and isinstance(value, int) and value < 1:
            raise RunError(f"{path}: {key}={value!r}; allowed: integers >= 1")
    if cfg["algo"] not in ALGOS:
        raise RunError(f"{path}: algo={cfg['algo']!r}; allowed: {sorted(ALGOS)}")
    return cfg


class RunLock:
    """An exclusive ``flock`` on ``run_dir/train.lock`` (which holds the owner's pid), held from :meth:`acquire`
    until :meth:`release` or the end of the process: the OS drops it when the process dies, even by kill -9,
    so a killed run can be resumed at once while a running one cannot be written by a second process."""

    def __init__(self, run_dir: Path) -> None:
        self.path = Path(run_dir) / LOCK
        self.fd: int | None = None

    def acquire(self) -> RunLock:
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            raise RunError(f"{self.path}: cannot create the run lock ({err.strerror or err})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            os.close(fd)
            raise RunError(f"{self.path.parent} is in use by another train.py (pid {pid})") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self.fd = fd
        return self

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)  # closing the only descriptor of the open file drops the flock
            self.fd = None

    def __enter__(self) -> RunLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _contents(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name != LOCK) if folder.is_dir() else []


def check_free(run_dir: Path, hint: str = "choose another --out or --resume it") -> None:
    """:class:`RunError` unless the output folder ``run_dir`` is absent or empty (a lone lock file counts as
    empty): nothing already there is overwritten."""
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise RunError(f"--out {run_dir} exists and is not a folder")
    if _contents(run_dir):
        raise RunError(f"--out {run_dir} exists and is not empty; {hint}")


def claim_run_dir(run_dir: Path) -> RunLock:
    """Create ``run_dir`` (or take an empty one) and lock it; :class:`RunError` if it is not empty (checked again
    under the lock, so of two processes racing for one folder exactly one gets it) or in use."""
    run_dir = Path(run_dir)
    check_free(run_dir)
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RunError(f"--out {run_dir} cannot be created ({err.strerror or err})") from None
    lock = RunLock(run_dir).acquire()
    try:
        check_free(run_dir)
    except RunError:
        lock.release()
        raise
    return lock


def env_spaces_venv(cfg: dict[str, Any], where: Path) -> VecEnv:
    """One env of the run's ``env_id`` / ``env_kwargs`` in a DummyVecEnv (for spaces and statistics);
    :class:`RunError` naming ``where`` (the config file) if it cannot be built."""
    try:
        return DummyVecEnv([lambda: gym.make(cfg["env_id"], **cfg["env_kwargs"])])
    except ENV_ERRORS as err:
        raise RunError(f"{where}: env {cfg['env_id']} with env_kwargs {cfg['env_kwargs']} cannot be built ({err})") from None


def hold_constant_features(obs: np.ndarray, normalizer: VecNormalize) -> np.ndarray:
    """``obs`` (n, F) with every feature that did not vary in training (:func:`constant_features`) set to its
    training mean.

    Such a feature (``log_n_frames`` when every training track had 500 frames, ``log_tau`` at one frame rate,
    ``frac_missing`` without gaps) told the policy nothing, and VecNormalize would divide any other value by
    √(var + ε) ≈ 2·10⁻⁴ and saturate it at ±``clip_obs``: an input the network never saw, which made
    sim-trained tuners collapse on OTB tracks of other lengths (measured: ufir_cmn, ``motion=otb
    sim_noise=box``, seed 1 on OTB replay, −0.322 against the rule saturated, +0.526 held). Holding it at the
    training value scores the track as the policy was trained to, from the features that did vary."""
    constant = constant_features(normalizer)
    if not constant.any():
        return obs
    held = np.array(obs, dtype=np.float32)
    rms = cast("RunningMeanStd", normalizer.obs_rms)  # one RunningMeanStd: a flat Box observation
    held[..., constant] = np.asarray(rms.mean, dtype=np.float32)[constant]
    return held


def constant_features(normalizer: VecNormalize) -> np.ndarray:
    """Mask (F,) of the features that did not vary in training: VecNormalize variance below
    :data:`CONSTANT_FEATURE_VAR` plus twice what the running statistics' prior leaves in a constant feature
    (:data:`PRIOR_COUNT`)."""
    rms = cast("RunningMeanStd", normalizer.obs_rms)  # one RunningMeanStd: a flat Box observation
    prior = 2.0 * PRIOR_COUNT * (1.0 + np.square(rms.mean)) / max(float(rms.count), PRIOR_COUNT)
    return np.asarray(rms.var) < CONSTANT_FEATURE_VAR + prior


def observation_names(env_id: str, env_kwargs: dict[str, Any]) -> tuple[str, ...]:
    """The names of the observation entries of ``env_id`` built with ``env_kwargs`` (FilterTune-v0: those of its
    feature set, :func:`bboxtune.envs.episodes.features.feature_names`; FilterRetune-v0:
    :func:`bboxtune.envs.retune_env.retune_observation_names`)."""
    cfg = EnvConfig.from_kwargs(**env_kwargs)
    return retune_observation_names(cfg) if env_id == RETUNE_ID else feature_names(cfg.features)


def describe_held_features(normalizers: dict[str, VecNormalize | None],
                           names: dict[str, tuple[str, ...]] | None = None) -> str:
    """Which inputs each trained tuner (name → its VecNormalize) holds at its training value, for a summary's
    settings ("none" if no tuner holds any): ``"ppo, ppo_best: frac_missing, log_n_frames"``, named by ``names``
    (tuner → its observation's names, :func:`observation_names`; default ``FEATURE_NAMES``, entries past the
    names as ``obs[i]``)."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for name, normalizer in normalizers.items():
        held = constant_features(normalizer) if normalizer is not None else np.zeros(0, dtype=bool)
        known = (names or {}).get(name, FEATURE_NAMES)
        features = tuple(known[i] if i < len(known) else f"obs[{i}]" for i in np.flatnonzero(held))
        groups.setdefault(features, []).append(name)
    if not any(groups):
        return "none"
    return "; ".join(f"{', '.join(names)}: {', '.join(features) or 'none'}" for features, names in groups.items())


class SB3Policy(ObsPolicy):
    """A trained SB3 tuner: VecNormalize's observation statistics, then the deterministic policy. Features that
    were constant in training are held at their training value (:func:`hold_constant_features`).

    A recurrent policy (``ppo_lstm``) keeps its LSTM state across the steps of an episode in :meth:`act`
    (reset by :meth:`begin_episode`); :meth:`predict` treats every row as the first step of its own episode."""

    def __init__(self, model: BaseAlgorithm, normalizer: VecNormalize | None, name: str, recurrent: bool = False) -> None:
        self.model = model
        self.normalizer = normalizer
        self.name = name
        self.recurrent = recurrent
        self._state: Any = None  # the LSTM state after the episode's last act (recurrent only)
        self._normalization: ObsNormalization | None = None  # the normalizer's arrays, built when first needed

    def _normalized(self, obs: np.ndarray) -> np.ndarray:
        """``normalizer.normalize_obs(hold_constant_features(obs))`` bit for bit, from arrays computed once per
        statistics (:mod:`bboxtune.agents.training.obs_normalization`)."""
        obs = np.asarray(obs, dtype=np.float32)
        if self.normalizer is None:
            return obs
        if self._normalization is None or not self._normalization.matches(self.normalizer):
            self._normalization = ObsNormalization.of(self.normalizer, constant_features(self.normalizer))
        return self._normalization.apply(obs)

    def predict(self, obs: np.ndarray) -> np.ndarray:
        obs = self._normalized(obs)
        if self.recurrent:
            actions, _ = self.model.predict(obs, episode_start=np.ones(len(obs), dtype=bool), deterministic=True)
        else:  # SB3's deterministic predict, bit for bit, without its per-call overhead
            actions = deterministic_actions(self.model.policy, obs)
        return np.asarray(actions, dtype=np.float64).reshape(len(obs), -1)

    def begin_episode(self) -> None:
        self._state = None

    def act(self, obs: np.ndarray, env: gym.Env | None = None) -> np.ndarray:
        if not self.recurrent:
            return self.predict(np.asarray(obs)[None])[0]
        first = np.array([self._state is None])
        actions, self._state = self.model.predict(self._normalized(np.asarray(obs)[None]), state=self._state,
                                                  episode_start=first, deterministic=True)
        return np.asarray(actions, dtype=np.float64).reshape(-1)

    @classmethod
    def load(cls, run_dir: Path, which: str = "final", *, trust_pickle: bool = False,
             venv: VecEnv | None = None) -> SB3Policy:
        """The ``"final"`` (``model.zip``) or ``"best"`` (``best_model.zip``, best on the val split) tuner of a run,
        loaded without unpickling (``trust_pickle``: accept an old run's ``vecnormalize.pkl``, see
        :func:`bboxtune.agents.training.run_files.load_normalizer`); :class:`RunError` naming the file that is missing, unreadable
        or inconsistent with ``config.yml``. ``venv``: an env with the spaces of the config's env, used in its place
        (:mod:`bboxtune.agents.smoothing.tuner` passes one that needs no data set); default: the config's env itself."""
        if which not in ("final", "best"):
            raise ValueError(f"which={which!r}; allowed: 'final', 'best'")
        run_dir = Path(run_dir)
        cfg = load_config(run_dir)
        prefix = "" if which == "final" else "best_"
        model_path = run_dir / f"{prefix}model.zip"
        if not model_path.exists():
            raise RunError(f"{model_path} not found (is the run finished? resume it with train.py --resume {run_dir})")
        venv = venv if venv is not None else env_spaces_venv(cfg, run_dir / CONFIG)
        model = load_model(model_path, cfg, venv)
        normalizer = load_normalizer(run_dir, venv, prefix=prefix, trust_pickle=trust_pickle)
        try:
            normalize = load_hyperparams(cfg["algo"], cfg["env_id"], cfg["hyperparams"]).normalize
        except ValueError as err:
            raise RunError(f"{run_dir / CONFIG}: hyperparams: {err}") from None
        if normalize and normalizer is None:
            raise RunError(f"{run_dir / (prefix + 'vecnormalize.json')} not found, but config.yml's hyperparams normalise "
                           "observations")
        if normalizer is not None:
            normalizer.training, normalizer.norm_reward = False, False
        return cls(model, normalizer, name=cfg["algo"], recurrent=cfg["algo"] in RECURRENT)
