#!/usr/bin/env python
"""Frames → detections → filter → scored boxes, for one video.

    python scripts/track_video.py --synthetic --detector template --filter ufir_cmn --seed 3 --out runs/track
    python scripts/track_video.py --video clip.mp4 --init 120,80,40,60 --detector sift --filter kf
    python scripts/track_video.py --frames $OTB/Car4 --detector template --filter ufir_cmn --otb-root $OTB_ROOT
    python scripts/track_video.py --synthetic --detector orb --tuned runs/video_table/tuned/orb-kf.json

The command is :func:`bboxtune.agents.commands.track_video.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.track_video import main

if __name__ == "__main__":
    raise SystemExit(main())
