"""The stable-baselines3 algorithms a tuner can be trained with (one dict, as RL Baselines3 Zoo)."""

from __future__ import annotations

from sb3_contrib import RecurrentPPO
from stable_baselines3 import A2C, PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm

# ppo_lstm (the RL Zoo's name for sb3-contrib's RecurrentPPO): PPO with an LSTM policy, for the sequential
# re-tuning env (FilterRetune-v0), whose policy may want a memory of the windows before the one it observes
ALGOS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3, "a2c": A2C, "ppo_lstm": RecurrentPPO}
RECURRENT = frozenset({"ppo_lstm"})  # algorithms whose policy carries a state from step to step


def algo_class(name: str) -> type[BaseAlgorithm]:
    """The SB3 class of algorithm ``name`` (a key of :data:`ALGOS`)."""
    if name not in ALGOS:
        raise ValueError(f"algo={name!r}; allowed: {sorted(ALGOS)}")
    return ALGOS[name]
