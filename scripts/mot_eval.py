"""Score box filters on real detection streams: MOT15 identities, public detections matched to the ground truth.

    python scripts/mot_eval.py --mot-root ../shared/data/mot15 --split test --out runs/mot_eval

The command is :func:`bboxtune.agents.commands.mot_eval.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.mot_eval import main

if __name__ == "__main__":
    raise SystemExit(main())
