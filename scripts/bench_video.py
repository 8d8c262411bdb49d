#!/usr/bin/env python
"""Speed of the video front end: synthetic rendering (s per 200-frame 320×240 video) and detector frame rates.

    python scripts/bench_video.py [--videos 5] [--frames 200]

The command is :func:`bboxtune.agents.commands.bench_video.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.bench_video import main

if __name__ == "__main__":
    raise SystemExit(main())
