"""The up-front checks of a ``scripts/train.py`` run (also run per setting by ``scripts/sweep.py`` before Ray
starts): its hyperparameters, its envs (built and reset as the workers will build them, and their memory), the
tensorboard extra and the model itself (built and dropped). Each failure is a :class:`RunError` naming the flags or
file at fault, so the command can refuse in one line before it writes anything."""

from __future__ import annotations

from typing import Any, cast

from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from bboxtune.agents.training.algos import algo_class
from bboxtune.agents.training.footprint import check_training_memory
from bboxtune.agents.training.hyperparams import Hyperparams, constructor_kwargs, load_hyperparams
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import ENV_ERRORS, make_env, make_vec
from bboxtune.envs.data.memory import MemoryLimitError

MODEL_ERRORS = (ValueError, TypeError, KeyError, AssertionError)  # what SB3 constructors raise for bad settings


def hyperparams_of(cfg: dict[str, Any], where: str) -> Hyperparams:
    """The run's hyperparameters (its YAML entry with the config's overrides); RunError naming ``where``."""
    try:
        return load_hyperparams(cfg["algo"], cfg["env_id"], cfg["hyperparams"])
    except ValueError as err:
        raise RunError(f"{where}: {err}") from None


def validated_envs(cfg: dict[str, Any], hp: Hyperparams, where: str, sizes: str) -> VecEnv:
    """What the worker processes will build, built here first: one env of the train and of the val split (each
    reset once) and the ``n_envs`` training envs (in this process: batched or DummyVecEnv), which are returned.
    :class:`RunError` naming ``where`` (the flags or the config file) if any of it fails, or ``sizes`` (where n_envs
    and the buffer's size are set) if the run would not fit in memory (``bboxtune.agents.training.footprint``)."""
    env_id, kwargs = cfg["env_id"], cfg["env_kwargs"]
    try:
        for split in ("train", "val"):
            env = make_env(env_id, kwargs, split=split)
            env.reset(seed=int(cfg["seed"]))
            env.close()
            if split == "train":
                check_training_memory(hp, env)
        return make_vec(env_id, kwargs, split="train", n_envs=hp.n_envs, seed=int(cfg["seed"]),
                        vec_env="batched" if hp.vec_env == "batched" else "dummy")
    except MemoryLimitError as err:
        raise RunError(f"{sizes}: {err}") from None
    except ENV_ERRORS as err:
        why = " ".join(str(err).split()).split(" was raised from the environment creator")[0]  # gymnasium's suffix
        raise RunError(f"{where}: env {env_id} with {kwargs}: {why}") from None


def check_tensorboard(cfg: dict[str, Any]) -> None:
    """With ``--tensorboard``, the tensorboard package must be importable (an optional extra)."""
    if cfg["tensorboard"]:
        try:
            import tensorboard  # noqa: F401
        except ImportError:
            raise RunError("--tensorboard needs the tensorboard package: pip install tensorboard") from None


def check_new_model(cfg: dict[str, Any], hp: Hyperparams, venv: VecEnv, where: str) -> None:
    """Build (and drop) the run's model on ``venv``: catches settings SB3's constructor refuses."""
    try:
        norm = VecNormalize(venv, **hp.normalize) if hp.normalize else venv
        n_actions = cast("tuple[int, ...]", venv.action_space.shape)[0]  # a Box
        algo_class(cfg["algo"])(hp.policy, norm, device="cpu", **constructor_kwargs(hp, n_actions))
    except MODEL_ERRORS as err:
        raise RunError(f"{where}: the {cfg['algo']} model cannot be built ({' '.join(str(err).split())})") from None
