"""A loaded tuner's observation normalisation with its constant arrays computed once, not on every call.

``SB3Policy`` normalises an observation as ``VecNormalize.normalize_obs(hold_constant_features(obs, normalizer))``
(:mod:`bboxtune.agents.training.runs`): the features constant in training set to their training mean (float32),
then ``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)`` as float32. That recomputes the constant
mask, ``sqrt(var + epsilon)`` and a deep copy on every call — most of the normalisation's cost for one observation of
a tracker's re-tune. :class:`ObsNormalization` keeps those arrays and runs the same numpy operations on the same
dtypes, so its output is bit for bit ``normalize_obs``'s (tested). It belongs to the statistics it was built from:
:meth:`ObsNormalization.matches` says whether a normaliser still holds them (``RunningMeanStd.update`` assigns new
``mean`` / ``var`` arrays, so an update is seen; its settings ``epsilon``, ``clip_obs`` and ``norm_obs`` are compared).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

if TYPE_CHECKING:
    from stable_baselines3.common.running_mean_std import RunningMeanStd
    from stable_baselines3.common.vec_env import VecNormalize


@dataclass(frozen=True, eq=False)
class ObsNormalization:
    """The arrays of one VecNormalize's flat-Box observation statistics that normalising an observation needs."""

    source: tuple[object, object, object, float, float, bool]  # (mean, var, count, epsilon, clip_obs, norm_obs) read
    constant: np.ndarray | None  # (F,) bool: features held at their training mean; None if there are none
    held: np.ndarray  # (F,) float32: the training mean, the value a constant feature is held at
    mean: np.ndarray  # (F,) float64
    std: np.ndarray  # (F,) float64: sqrt(var + epsilon)
    clip: float  # clip_obs
    normalize: bool  # norm_obs: False leaves the observation as held

    @classmethod
    def of(cls, normalizer: VecNormalize, constant: np.ndarray) -> ObsNormalization:
        """The normalisation of ``normalizer`` holding the features ``constant`` (F,) bool
        (:func:`bboxtune.agents.training.runs.constant_features`)."""
        rms = cast("RunningMeanStd", normalizer.obs_rms)  # one RunningMeanStd: a flat Box observation
        return cls(source=_source(normalizer), constant=constant if constant.any() else None,
                   held=np.asarray(rms.mean, dtype=np.float32), mean=rms.mean, std=np.sqrt(rms.var + normalizer.epsilon),
                   clip=normalizer.clip_obs, normalize=normalizer.norm_obs)

    def matches(self, normalizer: VecNormalize) -> bool:
        """Whether ``normalizer`` still holds the statistics and settings this was built from."""
        now = _source(normalizer)
        return all(a is b for a, b in zip(now[:3], self.source[:3], strict=True)) and now[3:] == self.source[3:]

    def apply(self, obs: np.ndarray) -> np.ndarray:
        """Observations ``obs`` (n, F) float32 held and normalised: ``normalize_obs(hold_constant_features(obs))``
        (a new array)."""
        if self.constant is not None:
            obs = np.array(obs, dtype=np.float32)
            obs[..., self.constant] = self.held[self.constant]
        if not self.normalize:
            return np.array(obs)
        return np.clip((obs - self.mean) / self.std, -self.clip, self.clip).astype(np.float32)


def _source(normalizer: VecNormalize) -> tuple[object, object, object, float, float, bool]:
    rms = cast("RunningMeanStd", normalizer.obs_rms)
    return rms.mean, rms.var, rms.count, float(normalizer.epsilon), float(normalizer.clip_obs), bool(normalizer.norm_obs)
