"""The deterministic action of a loaded (non-recurrent) SB3 policy without ``BasePolicy.predict``'s per-call overhead.

``policy.predict(obs, deterministic=True)`` switches the whole module tree to eval mode (``module.train(False)`` on
every submodule), checks and converts the observation, builds the action distribution and reads its mode — about
0.5 ms for one 20-feature observation, most of a tuner's call inside a tracker. :func:`deterministic_actions` runs the
same torch float32 operations on the same tensors, so its actions are bit for bit those of ``predict`` (tested on the
shipped tuners and random observations):

* eval mode is set only when the policy is in training mode (after ``learn``), not on every call;
* an actor-critic policy with a diagonal Gaussian (PPO's, A2C's default ``MlpPolicy``) returns its action net's
  output on the actor latent, which is what the distribution's mode (its mean) is, without building the
  distribution; every other policy (SAC, TD3, state-dependent noise) runs its own ``_predict``;
* then, as ``predict``: actions as numpy (n, *action shape), unscaled from [-1, 1] for a squashing policy, else
  clipped to the action space.
"""

from __future__ import annotations

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel, BasePolicy


def deterministic_actions(policy: BasePolicy, obs: np.ndarray) -> np.ndarray:
    """``policy.predict(obs, deterministic=True)[0]`` for observations ``obs`` (n, *observation shape) (module
    docstring): the actions (n, *action shape)."""
    if policy.training:
        policy.set_training_mode(False)
    with th.no_grad():
        x = th.as_tensor(obs, device=policy.device)
        if isinstance(policy, ActorCriticPolicy) and type(policy.action_dist) is DiagGaussianDistribution:
            features = BaseModel.extract_features(policy, x, policy.pi_features_extractor)
            actions = policy.action_net(policy.mlp_extractor.forward_actor(features))
        else:
            actions = policy._predict(x, deterministic=True)
    out = actions.cpu().numpy().reshape((-1, *policy.action_space.shape))  # type: ignore[misc]
    if isinstance(policy.action_space, spaces.Box):
        if policy.squash_output:
            return np.asarray(policy.unscale_action(out))
        return np.clip(out, policy.action_space.low, policy.action_space.high)
    return out
