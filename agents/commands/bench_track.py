"""Speed of the SORT-style tracker (bboxtune.agents.tracking) on MOT15 public detections, per filter, with SORT's
filter (sort_kf) measured in the same run as the peer.

    python scripts/bench_track.py [--mot-root ../shared/data/mot15] [--repeat 3] [--filters sort_kf bytetrack_kf search]

Every filter tracks every sequence of the data folder (SORT's settings); the best of --repeat runs is kept. Prints
frames/s and detections/s per filter and the ratio to sort_kf's rate. The filters' timed runs alternate (every
filter once, then again, --repeat times), so that a change of the machine's load hits all of them. Speed is never
asserted by the tests; run on an idle machine for meaningful numbers.
"""

from __future__ import annotations

import time

from bboxtune.agents.cli import ArgumentParser, command, existing_dir, positive_int
from bboxtune.agents.commands.track_mot import DEFAULT_PRETRAINED, FILTERS
from bboxtune.agents.smoothing.tuner import load_pretrained
from bboxtune.agents.tracking.sort_tracker import SEARCH, TUNED, make_tracker
from bboxtune.envs.data.mot import resolve_root
from bboxtune.envs.data.mot_io import read_detections, read_sequences_csv

NOISE: dict[str, float] = {"sigma_w": 300.0, "sigma_v": 3.0}  # px/s², px: a plausible setting for pedestrians at 7–30 fps
PARAMS: dict[str, dict[str, float]] = {
    "kf": NOISE, "kf_cmn": {**NOISE, "psi": 0.3}, "ufir": {"horizon": 8}, "ufir_cmn": {"horizon": 8, "psi": 0.3},
    "ofir": {**NOISE, "horizon": 8}, "oufir": {**NOISE, "horizon": 8}, "fir": {**NOISE, "horizon": 8}, "ukf": NOISE}


@command
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(prog="bench_track.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--mot-root", type=existing_dir, default=None, help="MOT15 data folder (default: $MOT_ROOT)")
    p.add_argument("--repeat", type=positive_int, default=3, help="runs per filter; the fastest counts (default 3)")
    p.add_argument("--filters", nargs="+", choices=FILTERS, default=["sort_kf", "bytetrack_kf", "kf", "ufir_cmn", TUNED, SEARCH])
    args = p.parse_args(argv)
    try:
        root = resolve_root(args.mot_root)
        table = read_sequences_csv(root)
        data = [(read_detections(root / name / "det" / "det.txt"), info) for name, info in table.items()]
        tuner = load_pretrained(DEFAULT_PRETRAINED) if TUNED in args.filters else None
    except (ValueError, OSError) as err:
        p.error(f"--mot-root: {err}")
    names = ["sort_kf", *(f for f in args.filters if f != "sort_kf")]  # the peer first
    frames = sum(info.frames for _, info in data)
    detections = sum(len(det.frame) for det, _ in data)
    best = dict.fromkeys(names, float("inf"))
    for _ in range(args.repeat):  # the filters alternate, so that a change of load hits every one of them
        for name in names:
            start = time.perf_counter()
            for det, info in data:
                tracker = make_tracker(name, 1.0 / info.fps, params=PARAMS.get(name),
                                       tuner=tuner if name == TUNED else None)
                for _ in tracker.run(det.frame, det.box, det.score, info.frames):
                    pass
            best[name] = min(best[name], time.perf_counter() - start)
    rates = {name: frames / seconds for name, seconds in best.items()}
    for name in names:
        print(f"{name:13s} {rates[name]:8.0f} frames/s {detections / best[name]:9.0f} detections/s "
              f"{rates[name] / rates['sort_kf']:6.2f}x sort_kf")
    print(f"({len(data)} sequences, {frames} frames, {detections} detections; best of {args.repeat})")
    return 0
