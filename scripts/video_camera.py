#!/usr/bin/env python
"""Camera-motion compensation on synthetic videos with a moving camera: RMSE with and without it.

    python scripts/video_camera.py                                   # 12 videos, template detector
    python scripts/video_camera.py --detector orb --n-videos 20 --out runs/video_camera

The command is :func:`bboxtune.agents.commands.video_camera.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.video_camera import main

if __name__ == "__main__":
    raise SystemExit(main())
