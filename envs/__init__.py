"""bboxtune environments, episode sources (simulator, OTB-100 replay) and OTB-standard metrics.

Importing this package registers, in one place:

* ``bboxtune/FilterTune-v0`` — :class:`envs.tune_env.FilterTuneEnv` (one step per track);
* ``bboxtune/FilterRetune-v0`` — :class:`envs.retune_env.FilterRetuneEnv` (re-tune every window of W frames).

Both without Gymnasium's passive env checker (``disable_env_checker=True``): in Gymnasium 1.4 that wrapper
fails every later ``step`` once its first ``reset`` raised, so a rejected reset would break the env; the
tests run Gymnasium's and SB3's full checkers instead.
"""

from gymnasium.envs.registration import register, registry

ENV_IDS = ("bboxtune/FilterTune-v0", "bboxtune/FilterRetune-v0")

for _id, _entry in zip(ENV_IDS, ("envs.tune_env:FilterTuneEnv", "envs.retune_env:FilterRetuneEnv")):
    if _id not in registry:
        register(id=_id, entry_point=_entry, disable_env_checker=True)
