"""Track MOT Challenge detections with a SORT-style tracker and a pluggable (or causally tuned) box filter.

    python scripts/track_mot.py --det ../shared/data/mot15/KITTI-13/det/det.txt --filter sort_kf --out runs/KITTI-13.txt
    python scripts/track_mot.py --det DET.txt --filter tuned --pretrained mot15_det --out runs/tuned/SEQ.txt

The command is :func:`bboxtune.agents.commands.track_mot.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.track_mot import main

if __name__ == "__main__":
    raise SystemExit(main())
