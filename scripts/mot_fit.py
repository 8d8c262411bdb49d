"""Fit the simulator's detection noise to MOT15's train split and show the fit (real vs fitted sim).

    python scripts/mot_fit.py --mot-root ../shared/data/mot15 --out docs/results/mot15_noise [--episodes 500] [--seed 0]

The command is :func:`bboxtune.agents.commands.mot_fit.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.mot_fit import main

if __name__ == "__main__":
    raise SystemExit(main())
