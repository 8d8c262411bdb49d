#!/usr/bin/env python
"""Train a filter tuner (stable-baselines3) on a bboxtune env and write a run directory.

    python scripts/train.py                      # PPO, bboxtune/FilterTune-v0, sim source, ufir_cmn back end
    python scripts/train.py --backend kf_cmn --seed 1
    python scripts/train.py --resume runs/ppo_ufir_cmn_sim_s0   # continue a killed run
    python scripts/train.py --resume runs/ppo_ufir_cmn_sim_s0 --timesteps 200000   # train it on to 200k in all

The command is :func:`bboxtune.agents.commands.train.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.train import main

if __name__ == "__main__":
    raise SystemExit(main())
