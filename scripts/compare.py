#!/usr/bin/env python
"""Compare a trained tuner with every baseline on the same held-out episodes of an env and back end.

    python scripts/compare.py --model runs/ppo_ufir_cmn_sim_s0 --episodes 500
    python scripts/compare.py --model runs/ppo_ufir_cmn_sim_s0 --env-kwargs source=otb          # transfer: OTB replay
    python scripts/compare.py --model RUN --env-kwargs source=otb_tracker "trackers=[SiamRPN++, CFNet, STRUCK, MDNet]"
    python scripts/compare.py --model runs/ppo_s0 runs/ppo_s1 runs/ppo_s2 --out runs/ppo_seeds   # across training seeds

The command is :func:`bboxtune.agents.commands.compare.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.compare import main

if __name__ == "__main__":
    raise SystemExit(main())
