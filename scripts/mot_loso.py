"""Leave-one-sequence-out evaluation of learned tuners on MOT15 detection streams: every identity scored by tuners
that never saw its sequence.

    python scripts/mot_loso.py --mot-root ../shared/data/mot15 --runs runs/mot_loso --out runs/mot_loso_table

The command is :func:`bboxtune.agents.commands.mot_loso.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.mot_loso import main

if __name__ == "__main__":
    raise SystemExit(main())
