"""Leave-one-sequence-out evaluation of the tracker's causal prediction search against the stock filters on MOT15.

    python scripts/track_loso.py --mot-root ../shared/data/mot15 --out docs/results/tracking/loso.csv

The command is :func:`bboxtune.agents.commands.track_loso.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.track_loso import main

if __name__ == "__main__":
    raise SystemExit(main())
