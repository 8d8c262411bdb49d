#!/usr/bin/env python
"""Detector × filter table on seeded synthetic videos: raw success AUC and filtered AUC (rule, tuned).

    python scripts/video_table.py                              # 100 test + 16 train videos, all detectors
    python scripts/video_table.py --backends ufir_cmn kf --cache ~/.cache/bboxtune/video --out runs/video_table
    python scripts/video_table.py --tuned runs/ppo_ufir_cmn_video_s0     # a train.py run (or a tuned.json)

The command is :func:`bboxtune.agents.commands.video_table.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.video_table import main

if __name__ == "__main__":
    raise SystemExit(main())
