"""Load an SB3 ``model.zip`` without unpickling anything from it, and check that it fits the run's config.

SB3's ``BaseAlgorithm.load`` cloudpickle-loads every entry of the zip's ``data`` JSON that is stored as
``{":serialized:": <base64 pickle>}`` (the spaces, the policy class, schedules, buffer classes, action noise, …)
unless the same key is given in ``custom_objects``; a planted pickle there runs code. :func:`load_model` reads
the ``data`` JSON itself and passes a ``custom_objects`` entry for *every* serialized key, rebuilt from the run's
config: an instance of the algorithm is constructed from ``config.yml``'s hyperparameters on the env's spaces
(without building networks) and each key takes that instance's attribute of the same name (spaces from the
env, the policy class from the algorithm's aliases, schedules, buffer classes and action noise from the
hyperparameters). A serialized key it cannot rebuild is refused, never unpickled. The network weights
(``policy.pth`` etc.) are read by SB3 with ``torch.load(weights_only=True)`` (so in the installed 2.9; torch >= 2.6,
which the project pins, defaults to it anyway; tests/agents/training/test_safe_load.py plants a pickle there), which
refuses anything but tensors and plain containers; ``policy_kwargs`` (the architecture) also come from the
config, so weights of another architecture fail to load (``exact_match``).

Consistency: the ``data`` JSON's plain shape/dtype of both spaces must equal the env's, and a model saved by
``scripts/train.py`` carries :data:`RUN_ENV` (env id and kwargs of its run), which must equal the config's.
:func:`check_env_match` checks a loaded model against another env it is to act in (``compare.py --env-kwargs``):
equal spaces, and actions that set the same parameters of the same back end through the same mapping.
"""

from __future__ import annotations

import io
import json
import pickle
import warnings
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecEnv

from bboxtune.agents.training.algos import algo_class
from bboxtune.agents.training.hyperparams import constructor_kwargs, load_hyperparams
from bboxtune.agents.training.run_files import RunError
from bboxtune.envs.data import textfile
from bboxtune.envs.episodes.config import EnvConfig

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.track_env import TrackEnv

Shape = tuple[int, ...]  # a Box space's shape (gymnasium types Space.shape as optional)

MAX_MODEL_BYTES = 2**30  # a model.zip of this project is a few hundred kB
RUN_ENV = "bboxtune_run_env"  # model attribute saved in data: {"env_id": ..., "env_kwargs": ...}
_SERIALIZED = ":serialized:"
_LOAD_ERRORS = (ValueError, RuntimeError, KeyError, TypeError, AssertionError, AttributeError, IndexError, OSError,
                EOFError, zipfile.BadZipFile, pickle.UnpicklingError)


def run_env(cfg: dict[str, Any]) -> dict[str, Any]:
    """The env a run's models belong to, as JSON would give it back (tuples become lists)."""
    return json.loads(json.dumps({"env_id": cfg["env_id"], "env_kwargs": cfg["env_kwargs"]}))


def stamp(model: BaseAlgorithm, cfg: dict[str, Any]) -> None:
    """Record the run's env in ``model`` (saved with it, as plain JSON, by ``model.save``)."""
    setattr(model, RUN_ENV, run_env(cfg))


def read_data(path: Path, raw: bytes) -> dict[str, Any]:
    """The ``data`` JSON of the zip archive ``raw`` (the bytes of ``path``; not deserialised) after checking every
    member's CRC."""
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as archive:
            bad = archive.testzip()
            if bad is not None:
                raise RunError(f"{path}: member {bad} is corrupt (CRC mismatch)")
            names = archive.namelist()
            if "data" not in names or "policy.pth" not in names:
                raise RunError(f"{path}: not an SB3 model (members {names}; expected data and policy.pth)")
            text = archive.read("data").decode("utf-8")
    except (OSError, EOFError, zipfile.BadZipFile, zipfile.LargeZipFile, UnicodeDecodeError) as err:
        raise RunError(f"{path}: not a readable zip archive ({err})") from None
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as err:
        raise RunError(f"{path}: its data entry is not valid JSON ({err})") from None
    if not isinstance(data, dict):
        raise RunError(f"{path}: its data entry is not a JSON object")
    return data


def _check_spaces(path: Path, data: dict[str, Any], venv: VecEnv) -> None:
    for key, space in (("observation_space", venv.observation_space), ("action_space", venv.action_space)):
        stored = data.get(key)
        if not isinstance(stored, dict):
            raise RunError(f"{path}: data has no {key}")
        shape, dtype = stored.get("_shape"), stored.get("dtype")
        if shape is not None and (list(shape) != list(cast(Shape, space.shape)) or str(dtype) != str(space.dtype)):
            raise RunError(f"{path}: {key} {dtype}{list(shape)} differs from the config's env "
                           f"({space.dtype}{list(cast(Shape, space.shape))}): the model does not belong to this run's "
                           "env/back end")


def replacements(path: Path, data: dict[str, Any], cfg: dict[str, Any], venv: VecEnv) -> dict[str, Any]:
    """``custom_objects`` for SB3's loader: every serialized key of ``data``, the spaces, the policy class and
    ``policy_kwargs``, taken from
    an unbuilt instance of the run's algorithm on ``venv`` with the config's hyperparameters."""
    try:
        hp = load_hyperparams(cfg["algo"], cfg["env_id"], cfg["hyperparams"])
        with warnings.catch_warnings():  # e.g. PPO's batch-size note for this venv's n_envs: not the run's
            warnings.simplefilter("ignore")
            # every class in ALGOS takes _init_setup_model; their declared base, BaseAlgorithm, does not
            template = algo_class(cfg["algo"])(hp.policy, venv, device="cpu", _init_setup_model=False,  # type: ignore[call-arg]
                                               **constructor_kwargs(hp, cast(Shape, venv.action_space.shape)[0]))
        template._setup_lr_schedule()
    except _LOAD_ERRORS as err:
        raise RunError(f"{path}: the run's hyperparams do not build a {cfg['algo']} model ({err})") from None
    serialized = [k for k, v in data.items() if isinstance(v, dict) and _SERIALIZED in v]
    unknown = [k for k in serialized if not hasattr(template, k)]
    if unknown:
        raise RunError(f"{path}: data entries {unknown} are pickled objects that cannot be rebuilt from config.yml; "
                       "refusing to unpickle them")
    fixed = ("observation_space", "action_space", "policy_class", "policy_kwargs")
    return {k: getattr(template, k) for k in {*serialized, *fixed}}


def load_model(path: Path, cfg: dict[str, Any], venv: VecEnv, **kwargs: Any) -> BaseAlgorithm:
    """The model ``path`` of the run whose config is ``cfg`` (``algo``, ``env_id``, ``env_kwargs``,
    ``hyperparams``), attached to ``venv`` (the run's env; its spaces are the reference), on the CPU, without
    unpickling anything; ``kwargs`` go to SB3's ``load`` (e.g. ``tensorboard_log``). :class:`RunError` naming
    the file if it is unreadable, corrupt, holds a pickle it would need, or belongs to another env/back end."""
    path = Path(path)
    try:
        raw = textfile.read_bytes(path, MAX_MODEL_BYTES)  # read once: the checks and SB3's loader see these bytes
    except ValueError as err:
        raise RunError(str(err)) from None
    data = read_data(path, raw)
    _check_spaces(path, data, venv)
    stamped = data.get(RUN_ENV)
    if stamped is not None and stamped != run_env(cfg):
        raise RunError(f"{path} was trained on {stamped}, but config.yml says {run_env(cfg)}")
    custom = replacements(path, data, cfg, venv)
    try:
        model = algo_class(cfg["algo"]).load(io.BytesIO(raw), env=venv, device="cpu", custom_objects=custom, **kwargs)
    except _LOAD_ERRORS as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise RunError(f"{path}: cannot be loaded as the {cfg['algo']} model config.yml describes ({first})") from None
    if not isinstance(model.num_timesteps, int) or model.num_timesteps < 0:
        raise RunError(f"{path}: num_timesteps={model.num_timesteps!r}")
    return model


def _space(space: gym.Space) -> str:
    return f"{space.dtype}{list(cast(Shape, space.shape))}"


def check_env_match(path: Path, model: BaseAlgorithm, cfg: dict[str, Any], env: gym.Env) -> None:
    """:class:`RunError` (one line naming the space and both shapes) unless ``model`` — of the run whose config is
    ``cfg`` — can act in ``env``: the observation and action spaces have equal shapes and dtypes, and an action
    means the same thing — the same back end, tuned parameters (``tune``) and action mapping (``horizon_max``,
    ``sigma_decades``). Everything else (source, split, track length, scenario ranges, …) may differ: that is a
    transfer evaluation."""
    for key in ("observation_space", "action_space"):
        mine, theirs = getattr(model, key), getattr(env, key)
        if mine.shape != theirs.shape or mine.dtype != theirs.dtype:
            raise RunError(f"{path}: {key} {_space(mine)} of the model differs from the evaluation env's "
                           f"{_space(theirs)}: the model cannot act in this env")
    try:
        run = EnvConfig.from_kwargs(**cfg["env_kwargs"])
    except (TypeError, ValueError) as err:
        raise RunError(f"{path}: the run's env_kwargs are not a valid env configuration ({err})") from None
    here = cast("TrackEnv", env.unwrapped).config
    if _meaning(run) != _meaning(here):
        raise RunError(f"{path}: action_space {_actions(run, model.action_space)} in its run, but "
                       f"{_actions(here, env.action_space)} in the evaluation env: the actions would mean other parameters")


def _meaning(cfg: EnvConfig) -> tuple[Any, ...]:
    """What an action sets: back end, tuned parameters, action mapping."""
    return cfg.backend, cfg.tune, cfg.horizon_max, cfg.sigma_decades


def _actions(cfg: EnvConfig, space: gym.Space) -> str:
    tune = cast("tuple[str, ...]", cfg.tune)  # EnvConfig resolves None to the back end's default
    return (f"{_space(space)} sets {list(tune)} of back end {cfg.backend} (horizon_max {cfg.horizon_max}, "
            f"sigma_decades {cfg.sigma_decades:g})")
