"""Speed of the SORT-style tracker per box filter on MOT15 detections, against SORT's own filter in the same run.

    python scripts/bench_track.py [--mot-root ../shared/data/mot15] [--repeat 3]

The command is :func:`bboxtune.agents.commands.bench_track.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.bench_track import main

if __name__ == "__main__":
    raise SystemExit(main())
