"""bboxtune environments, episode sources (simulator, OTB-100 replay) and OTB-standard metrics.

Importing this package registers, in one place:

* ``bboxtune/FilterTune-v0`` — :class:`envs.tune_env.FilterTuneEnv` (one step per track), with the batched
  :class:`envs.vector.TuneVectorEnv` as its ``vector_entry_point`` (``gym.make_vec`` / :func:`make_vec`);
* ``bboxtune/FilterRetune-v0`` — :class:`envs.retune_env.FilterRetuneEnv` (re-tune every window of W frames).

Both without Gymnasium's passive env checker (``disable_env_checker=True``): in Gymnasium 1.4 that wrapper
fails every later ``step`` once its first ``reset`` raised, so a rejected reset would break the env; the
tests run Gymnasium's and SB3's full checkers instead.
"""

from gymnasium.envs.registration import register, registry

TUNE_ID, RETUNE_ID = "bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0"
ENV_IDS = (TUNE_ID, RETUNE_ID)

_VECTOR_ENTRY_POINTS = {TUNE_ID: "envs.vector:TuneVectorEnv"}

for _id, _entry in zip(ENV_IDS, ("envs.tune_env:FilterTuneEnv", "envs.retune_env:FilterRetuneEnv")):
    if _id not in registry:
        register(id=_id, entry_point=_entry, vector_entry_point=_VECTOR_ENTRY_POINTS.get(_id), disable_env_checker=True)

from envs.vector import make_vec  # noqa: E402  (after registration: make_vec is gym.make_vec on these ids)

__all__ = ["ENV_IDS", "RETUNE_ID", "TUNE_ID", "make_vec"]
