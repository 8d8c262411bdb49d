"""Sweep train.py settings on Ray Tune (the optional extra bboxtune[ray]), each trial scored on the val split.

    python scripts/sweep.py --out runs/sweep --backends ufir_cmn kf_cmn --seeds 0 1 2 --hyperparams learning_rate:3e-4,1e-3
    python scripts/sweep.py --out runs/sweep --resume            # continue an interrupted sweep (the same flags)
    python scripts/sweep.py --out runs/sweep_smoke --smoke       # two tiny trials, seconds
    python scripts/sweep.py --out runs/sweep --address auto ...  # the same sweep on a running Ray cluster

The command is :func:`bboxtune.agents.commands.sweep.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.sweep import main

if __name__ == "__main__":
    raise SystemExit(main())
