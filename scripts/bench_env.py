"""Environment benchmark: how fast episodes go through ``gym.make`` + ``step`` and through batched scoring.

    python scripts/bench_env.py [--backend ufir_cmn] [--episodes 1000] [--candidates 256] [--track-length 500]

The command is :func:`bboxtune.agents.commands.bench_env.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.bench_env import main

if __name__ == "__main__":
    raise SystemExit(main())
