"""Measure OTB-100's ground-truth motion, fit the simulator's "otb" motion model, compare with the simulator.

    python scripts/otb_motion.py --otb-root ../shared/data/otb --out docs [--tracks 300] [--seed 0]

The command is :func:`bboxtune.agents.commands.otb_motion.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.otb_motion import main

if __name__ == "__main__":
    raise SystemExit(main())
