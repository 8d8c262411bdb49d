#!/usr/bin/env python
"""Smooth a tracker's OTB-format results with a learned tuner: parameters chosen per sequence from the
tracker's boxes alone (never the ground truth).

    python scripts/smooth.py --results trackers/SiamFC --out runs/SiamFC_smoothed
    python scripts/smooth.py --results trackers/SiamFC --out DIR --pretrained sim_ufir_cmn --otb-root $OTB_ROOT
    python scripts/smooth.py --results trackers/SiamFC --out DIR --model runs/ppo_ufir_cmn_otb_tracker_s0

The command is :func:`bboxtune.agents.commands.smooth.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.smooth import main

if __name__ == "__main__":
    raise SystemExit(main())
