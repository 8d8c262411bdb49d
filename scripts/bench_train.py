"""Training benchmark: the default ``python scripts/train.py`` run against SB3's PPO on CartPole-v1, same run.

    python scripts/bench_train.py [--timesteps 100000] [--out DIR] [-- TRAIN_ARGS ...]

The command is :func:`bboxtune.agents.commands.bench_train.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.bench_train import main

if __name__ == "__main__":
    raise SystemExit(main())
