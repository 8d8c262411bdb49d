"""Filter benchmark: batched back ends against per-step / per-point references, measured in the same run.

    python scripts/bench_filters.py [--tracks 256] [--frames 1000] [--ref-tracks 256] [--iter-tracks 4]
                                    [--wide-tracks 20000] [--wide-frames 500] [--missing 0.05]
                                    [--long-frames 1000000] [--sections reference backends wide long]

The command is :func:`bboxtune.agents.commands.bench_filters.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.bench_filters import main

if __name__ == "__main__":
    raise SystemExit(main())
