"""Speed of the video front end: synthetic rendering (s per 200-frame 320×240 video) and detector frame rates.

    python scripts/bench_video.py [--videos 5] [--frames 200]

Prints rates only (speed is never asserted by the tests). Run on an idle machine for meaningful numbers.
"""

from __future__ import annotations

import time

import numpy as np

from bboxtune.agents.cli import ArgumentParser, argument_errors, command, int_range, positive_int
from bboxtune.envs.episodes.config import TRACK_LENGTH_MAX
from bboxtune.envs.video.camera import background_shift
from bboxtune.envs.video.detectors import DETECTORS, detect_video, make_detector
from bboxtune.envs.video.synthetic import VideoRanges, synthetic_video


@command
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(prog="bench_video.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--videos", type=positive_int, default=5, help="synthetic videos (default 5)")
    p.add_argument("--frames", type=int_range(1, TRACK_LENGTH_MAX), default=200,
                   help=f"frames per video, at most {TRACK_LENGTH_MAX} (the envs' longest track; default 200)")
    args = p.parse_args(argv)
    ranges = VideoRanges(n_frames=args.frames)
    with argument_errors(p, "--frames"):
        ranges.sample(np.random.default_rng(0))  # the scenario's own checks (frame count), before any work
    start = time.perf_counter()
    videos = [list(synthetic_video(2_000_000 + i, ranges)) for i in range(args.videos)]
    render = (time.perf_counter() - start) / args.videos
    print(f"render: {render:.2f} s per {args.frames}-frame 320x240 video ({args.frames / render:.0f} frames/s)")
    truth = [synthetic_video(2_000_000 + i, ranges).boxes[0] for i in range(args.videos)]
    for name in DETECTORS:
        start = time.perf_counter()
        for frames, box in zip(videos, truth, strict=False):
            detect_video(make_detector(name), frames, box)
        rate = args.videos * args.frames / (time.perf_counter() - start)
        print(f"{name:9s} {rate:7.0f} frames/s")
    start = time.perf_counter()
    for frames in videos:
        background_shift(frames)
    print(f"camera shift estimate {args.videos * args.frames / (time.perf_counter() - start):7.0f} frames/s")
    return 0

