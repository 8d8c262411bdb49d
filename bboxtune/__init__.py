"""bboxtune: learned tuning of bounding-box smoothing filters.

One namespace, three parts (their sources are the repository's top-level folders ``filters/``, ``envs/`` and
``agents/``, mapped here by pyproject's ``package-dir``), each imported on first use:

* :mod:`bboxtune.filters` — the batched filters (KF, KF-CMN, UFIR, UFIR-CMN, OFIR, OUFIR, Kwon's FIR, UKF) and the
  box Kalman filters trackers ship (ByteTrack's, SORT's);
* :mod:`bboxtune.envs` — the Gymnasium environments, episode sources, OTB / MOT data and metrics;
* :mod:`bboxtune.agents` — the tuners (stable-baselines3 and non-learned baselines), :func:`bboxtune.agents.smooth`.

Importing ``bboxtune`` (or any part of it) registers the environment ids, in this one place, as Gymnasium's
third-party packages do:

* ``bboxtune/FilterTune-v0`` — :class:`bboxtune.envs.tune_env.FilterTuneEnv` (one step per track), with the
  batched :class:`bboxtune.envs.vector.TuneVectorEnv` as its ``vector_entry_point`` (``gym.make_vec``);
* ``bboxtune/FilterRetune-v0`` — :class:`bboxtune.envs.retune_env.FilterRetuneEnv` (re-tune every window of W
  frames).

Both without Gymnasium's passive env checker (``disable_env_checker=True``): in Gymnasium 1.4 that wrapper fails
every later ``step`` once its first ``reset`` raised, so a rejected reset would break the env; the tests run
Gymnasium's and SB3's full checkers instead.

>>> import gymnasium as gym
>>> import bboxtune
>>> gym.register_envs(bboxtune)
>>> gym.make("bboxtune/FilterTune-v0").spec.id
'bboxtune/FilterTune-v0'
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version
from types import ModuleType

from gymnasium.envs.registration import register, registry

TUNE_ID, RETUNE_ID = "bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"
ENV_IDS = (TUNE_ID, RETUNE_ID)

_ENTRY_POINTS = {TUNE_ID: ("bboxtune.envs.tune_env:FilterTuneEnv", "bboxtune.envs.vector:TuneVectorEnv"),
                 RETUNE_ID: ("bboxtune.envs.retune_env:FilterRetuneEnv", None)}
for _id, (_entry, _vector_entry) in _ENTRY_POINTS.items():
    if _id not in registry:
        register(id=_id, entry_point=_entry, vector_entry_point=_vector_entry, disable_env_checker=True)

_PARTS = ("filters", "envs", "agents")

try:
    __version__ = version("bboxtune")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "unknown"


def __getattr__(name: str) -> ModuleType:
    """``bboxtune.filters`` / ``.envs`` / ``.agents`` without importing them first (each is imported once)."""
    if name in _PARTS:
        return import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ENV_IDS", "RETUNE_ID", "TUNE_ID", "__version__", "agents", "envs", "filters"]
