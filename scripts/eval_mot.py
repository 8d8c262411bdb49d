"""Score a tracker's MOT Challenge results on MOT15 with motmetrics: MOTA, IDF1, ID switches (also per identity), MT/ML.

    python scripts/eval_mot.py --results runs/track_mot --gt-root ../shared/data/mot15 --out runs/track_mot_scores.csv

The command is :func:`bboxtune.agents.commands.eval_mot.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.eval_mot import main

if __name__ == "__main__":
    raise SystemExit(main())
