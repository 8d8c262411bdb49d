"""The deterministic action of a loaded (non-recurrent) SB3 policy without ``BasePolicy.predict``'s per-call overhead.

``policy.predict(obs, deterministic=True)`` switches the whole module tree to eval mode (``module.train(False)`` on
every submodule), checks and converts the observation, builds the action distribution and reads its mode — about
0.5 ms for one 20-feature observation, most of a tuner's call inside a tracker. :func:`deterministic_actions` runs the
same torch float32 operations on the same tensors, so its actions are bit for bit those of ``predict`` (tested on the
shipped tuners and random observations):

* eval mode is set only when the policy is in training mode (after ``learn``), not on every call;
* an actor-critic policy with a diagonal Gaussian (PPO's, A2C's default ``MlpPolicy``) returns its action net's
  output on the actor latent, which is what the distribution's mode (its mean) is, without building the
  distribution; its MLP layers (``Linear``, ``Tanh``, ``ReLU``) run as the functions their ``forward`` calls
  (``functional.linear``, ``torch.tanh``, ``functional.relu``) and a flat Box observation as ``obs.float()``
  (``preprocess_obs``) — other layers and extractors as modules; every other policy (SAC, TD3,
  state-dependent noise) runs its own ``_predict``;
* which of these paths a policy takes, its layers in order and the parameter whose device is the policy's are
  worked out once per policy (again when its action networks are replaced by other modules), not on every call;
* then, as ``predict``: actions as numpy (n, *action shape), unscaled from [-1, 1] for a squashing policy, else
  clipped to the action space.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast
from weakref import WeakKeyDictionary

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel, BasePolicy
from stable_baselines3.common.torch_layers import FlattenExtractor
from torch import nn
from torch.nn import functional


def deterministic_actions(policy: BasePolicy, obs: np.ndarray) -> np.ndarray:
    """``policy.predict(obs, deterministic=True)[0]`` for observations ``obs`` (n, *observation shape) (module
    docstring): the actions (n, *action shape)."""
    if policy.training:
        policy.set_training_mode(False)
    plan = _plan(policy)
    with th.no_grad():
        x = th.as_tensor(obs, device=plan.device())
        if plan.layers is not None:
            features = x.float().flatten(1) if plan.flat else BaseModel.extract_features(
                policy, x, cast(ActorCriticPolicy, policy).pi_features_extractor)
            actions = features
            for layer in plan.layers:
                actions = _apply(layer, actions)
        else:
            actions = policy._predict(x, deterministic=True)
    out = actions.cpu().numpy().reshape((-1, *policy.action_space.shape))  # type: ignore[misc]
    if isinstance(policy.action_space, spaces.Box):
        if policy.squash_output:
            return np.asarray(policy.unscale_action(out))
        return np.clip(out, policy.action_space.low, policy.action_space.high)
    return out


@dataclass(frozen=True, eq=False)
class _Plan:
    """How :func:`deterministic_actions` runs one policy, worked out once per policy and network (module docstring)."""

    networks: tuple[nn.Module, ...]  # the policy's action networks the plan was made from (a swapped one: a new plan)
    first: nn.Parameter | None  # the policy's first parameter: its device is the policy's (SB3's ``policy.device``)
    layers: tuple[nn.Module, ...] | None  # the Gaussian mean's layers in order, flattened; None: the policy's _predict
    flat: bool  # a flat Box observation through FlattenExtractor: ``obs.float().flatten(1)``

    def device(self) -> th.device:
        return self.first.device if self.first is not None else th.device("cpu")


_PLANS: WeakKeyDictionary[BasePolicy, _Plan] = WeakKeyDictionary()


def _networks(policy: BasePolicy) -> tuple[nn.Module, ...]:
    if isinstance(policy, ActorCriticPolicy) and type(policy.action_dist) is DiagGaussianDistribution:
        return policy.mlp_extractor.policy_net, policy.action_net
    return ()


def _plan(policy: BasePolicy) -> _Plan:
    """The policy's plan (cached while its action networks are the same modules)."""
    networks = _networks(policy)
    plan = _PLANS.get(policy)
    if plan is not None and len(plan.networks) == len(networks) and all(
            a is b for a, b in zip(plan.networks, networks, strict=True)):
        return plan
    flat = (isinstance(policy, ActorCriticPolicy) and type(policy.pi_features_extractor) is FlattenExtractor
            and isinstance(policy.observation_space, spaces.Box))
    layers = tuple(layer for network in networks for layer in _flattened(network)) if networks else None
    plan = _Plan(networks=networks, first=next(iter(policy.parameters()), None), layers=layers, flat=flat)
    _PLANS[policy] = plan
    return plan


def _flattened(layer: nn.Module) -> list[nn.Module]:
    """The layers a ``Sequential`` (exact type; nested ones too) runs in order; another module as itself."""
    if type(layer) is nn.Sequential:
        return [inner for child in layer for inner in _flattened(child)]
    return [layer]


def _apply(layer: nn.Module, x: th.Tensor) -> th.Tensor:
    """``layer(x)``; ``Linear`` / ``Tanh`` / ``ReLU`` (SB3's MLPs) by the functions their ``forward`` calls, without
    ``Module.__call__``'s hook dispatch (tens of µs a layer on a busy machine)."""
    kind = type(layer)  # exact types: a subclass may override forward
    if kind is nn.Linear:
        linear = cast(nn.Linear, layer)
        return functional.linear(x, linear.weight, linear.bias)
    if kind is nn.Tanh:
        return th.tanh(x)
    if kind is nn.ReLU and not cast(nn.ReLU, layer).inplace:
        return functional.relu(x)
    return cast(th.Tensor, layer(x))
