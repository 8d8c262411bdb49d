"""Frames → detections → filter → scored boxes, for one video.

    python scripts/track_video.py --synthetic --detector template --filter ufir_cmn --seed 3 --out runs/track
    python scripts/track_video.py --video clip.mp4 --init 120,80,40,60 --detector sift --filter kf
    python scripts/track_video.py --frames $OTB/Car4 --detector template --filter ufir_cmn --otb-root $OTB_ROOT
    python scripts/track_video.py --synthetic --detector orb --tuned runs/video_table/tuned/orb-kf.json

Filter parameters: the fixed rule (nominal σ = the detector's calibrated relative σ × the measured box scale,
N = N_opt; :mod:`bboxtune.envs.episodes.video_source`) or, with ``--tuned MODEL`` (a ``tuned.json`` or a ``train.py`` run
directory), the tuner's choice; ``--compensate`` estimates the camera motion from the frames and compensates
it (:mod:`bboxtune.envs.video.camera`; UKF: [Raj-UKF] eq. 17, other back ends: camera-velocity input, eq. 18).

Writes to ``--out`` (a new or empty folder, nothing is overwritten; default ``runs/track_video/<name>`` with name
``synthetic-<seed>``, the video's stem or the sequence): ``frames.csv`` (per frame: raw and filtered x, y, w, h [and
ground truth, IoUs]), ``summary.json`` (``raw_success_auc``, ``filtered_success_auc``, precision@20 px and the (cx,
cy, w, h) RMSE over the frames with a detection when ground truth is known, ``n_frames``, ``n_missing``, parameters),
and ``video.mp4`` (truth green, detection red, filtered blue; ``strip.png`` of 8 frames instead if no MP4 codec is
available). All files are written atomically. Box coordinates: 0-based for ``--synthetic`` / ``--video``; 1-based OTB
coordinates for ``--frames`` (``--init`` is read in the same convention). Arguments are checked before any frame is
read: a bad one gives one line naming it (exit status 2). A ``train.py`` run directory given to ``--tuned`` is loaded
without unpickling anything (``bboxtune.agents.training.safe_load``); an old run whose statistics are only in
``vecnormalize.pkl`` needs ``--trust-pickle`` (pickles can run code: only for runs you trust).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import cast

import cv2
import numpy as np
from tqdm import tqdm

from bboxtune import filters
from bboxtune.agents.cli import (
    ArgumentParser,
    box_xywh,
    command,
    existing_dir,
    existing_file,
    int_range,
    nonnegative_int,
    out_dir,
)
from bboxtune.agents.evaluation.video_tables import write_csv, write_json
from bboxtune.agents.smoothing.video_tuning import load_tuner
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import check_free
from bboxtune.envs.data import metrics
from bboxtune.envs.data.atomic_files import atomic_write
from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.episodes.actions import ACCEPTS, BACKENDS
from bboxtune.envs.episodes.config import TRACK_LENGTH_MAX, EnvConfig
from bboxtune.envs.episodes.video_source import VideoSettings, VideoSource
from bboxtune.envs.video.camera import frame_shift, run_compensated
from bboxtune.envs.video.detector import to_gray
from bboxtune.envs.video.detectors import DETECTORS, make_detector
from bboxtune.envs.video.frames import otb_frames, video_file
from bboxtune.envs.video.synthetic import VideoRanges, synthetic_video

_GREEN, _RED, _BLUE = (40, 170, 40), (40, 40, 220), (230, 80, 40)  # BGR


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="track_video.py", description=__doc__.split("\n\n")[0],
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter, allow_abbrev=False)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--synthetic", action="store_true", help="a synthetic video (seed --seed)")
    src.add_argument("--video", type=existing_file, help="a video file")
    src.add_argument("--frames", type=existing_dir, help="a folder of numbered images (OTB layout <Video>[/img]/0001.jpg)")
    p.add_argument("--init", type=box_xywh, help="initial box x,y,w,h (default: the first ground-truth box)")
    p.add_argument("--detector", default="template", choices=DETECTORS)
    p.add_argument("--filter", default=None, choices=BACKENDS,
                   help="back end (default: the tuner's, else ufir_cmn)")
    p.add_argument("--tuned", default=None, help="tuned.json or train.py run directory choosing the parameters")
    p.add_argument("--trust-pickle", action="store_true",
                   help="--tuned RUN_DIR: accept an old run's pickled vecnormalize.pkl (pickles can run code)")
    p.add_argument("--compensate", action="store_true", help="estimate and compensate camera motion")
    p.add_argument("--n-frames", type=int_range(2, TRACK_LENGTH_MAX), default=200,
                   help="--synthetic: frames (at most the env's track length limit)")
    p.add_argument("--sequence", default=None, help="--frames: OTB sequence name (default: the folder name)")
    p.add_argument("--otb-root", type=existing_dir, default=None,
                   help="--frames: OTB data folder with sequences.csv (default $OTB_ROOT)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="synthetic video seed")
    p.add_argument("--out", type=out_dir, default=None, help="output folder, new or empty (default runs/track_video/<name>)")
    p.add_argument("--no-video", action="store_true", help="skip the annotated MP4")
    return p


def open_source(args: argparse.Namespace) -> tuple[object, float, np.ndarray | None, float, str]:
    """(frames, fps, ground truth (T, 4) 0-based xywh or None, origin of the user's coordinates, name)."""
    if args.synthetic:
        video = synthetic_video(args.seed, VideoRanges(n_frames=args.n_frames))
        return video, 1.0 / video.tau, video.boxes, 0.0, f"synthetic-{args.seed}"
    if args.video:
        clip = video_file(args.video)
        return clip, clip.fps, None, 0.0, Path(args.video).stem
    frames, gt, name = otb_frames(args.frames, sequence=args.sequence, otb_root=args.otb_root)
    if gt is not None:
        gt = gt.copy()
        gt[:, :2] -= 1.0  # OTB 1-based → 0-based
    return frames, frames.fps, gt, 1.0, name


def user_box(box: tuple[float, float, float, float], origin: float) -> np.ndarray:
    """``--init`` (in the source's coordinate convention) as a 0-based x, y, w, h array."""
    return np.array(box, dtype=float) - [origin, origin, 0.0, 0.0]


def detect(frames, detector_name: str, init: np.ndarray, compensate: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """One pass over the frames: detections (T, 4) xywh (row 0 = ``init``) and, if ``compensate``, the
    background shift per frame (T, 2) px."""
    detector, rows, shifts, prev = make_detector(detector_name), [], [np.zeros(2)], None
    for n, frame in enumerate(tqdm(frames, total=len(frames) or None, desc="detect", unit="frame")):
        if n == 0:
            detector.start(frame, init)
            rows.append(np.asarray(init, dtype=float))
        else:
            rows.append(detector.detect(frame))
        if compensate:
            g = to_gray(frame)
            if prev is not None:
                shifts.append(frame_shift(prev, g))
            prev = g
    return np.vstack(rows), (np.vstack(shifts) if compensate else None)


def scores(raw: np.ndarray, est: np.ndarray, truth: np.ndarray) -> dict[str, float | None]:
    """Success AUC and precision@20 px of raw and filtered boxes (missing detections fail), and the
    (cx, cy, w, h) RMSE over the frames with a detection."""
    out: dict[str, float | None] = {}
    both = np.isfinite(raw).all(axis=1) & np.isfinite(truth).all(axis=1)
    for key, pred in (("raw", raw), ("filtered", est)):
        out[f"{key}_success_auc"] = float(metrics.success_auc(pred, truth))
        out[f"{key}_precision20"] = float(metrics.precision_score(pred, truth))
        err = xywh_to_cxcywh(pred[both]) - xywh_to_cxcywh(truth[both])
        out[f"{key}_rmse_detected_frames"] = float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if both.any() else None
    return out


@command
def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if (args.sequence or args.otb_root) and not args.frames:
        parser.error("--sequence and --otb-root apply to --frames only")
    try:
        frames, fps, gt, origin, name = open_source(args)
        out = args.out or Path("runs/track_video") / name
        check_free(out, "choose another --out")
        if args.init is None and (gt is None or not np.all(np.isfinite(gt[0]))):
            raise RunError("--init x,y,w,h is required when the first frame has no ground truth")
        init = user_box(args.init, origin) if args.init else cast(np.ndarray, gt)[0]  # gt checked above
        tuner = load_tuner(args.tuned, trust_pickle=args.trust_pickle) if args.tuned else None
        backend = args.filter or (tuner.backend if tuner else "ufir_cmn")
        if tuner is not None and tuner.backend != backend:
            raise RunError(f"--filter {backend} differs from the tuner's back end {tuner.backend}")
    except (RunError, ValueError, OSError) as err:
        parser.error(str(err))
    print(f"{name}: detector {args.detector}, filter {backend}, seed {args.seed}")

    t0 = time.time()
    try:
        y_xywh, shift = detect(frames, args.detector, init, args.compensate)
    except ValueError as err:  # an unreadable image or video frame, named by the reader
        parser.error(str(err))
    T = len(y_xywh)
    truth = gt[:T] if gt is not None else np.full((T, 4), np.nan)
    source = VideoSource(EnvConfig(track_length=max(T, 8)), VideoSettings(detector=args.detector))
    ep = source.episode({"truth": truth, "y": y_xywh, "tau": np.float64(1.0 / fps)}, meta={"sequence": name})
    params = tuner.params(ep) if tuner else ep.nominal.as_params()
    used = {k: (int(params[k][0]) if k == "horizon" else float(params[k][0])) for k in ACCEPTS[backend]}
    if shift is not None:
        states = run_compensated(backend, ep.y, shift, ep.tau, **used)
    else:
        states = filters.make(backend, filters.constant_velocity(ep.tau, ndim=4), **used).run(ep.y)
    est_xywh = cxcywh_to_xywh(states[:, :4])

    summary = {"name": name, "detector": args.detector, "filter": backend, "params": used, "seed": args.seed,
               "compensated": args.compensate, "tuned": args.tuned, "n_frames": T,
               "n_missing": int(np.isnan(y_xywh).any(axis=1).sum()), "fps": fps, "coordinate_origin": origin,
               "seconds": round(time.time() - t0, 2)}
    header = ["frame", "raw_x", "raw_y", "raw_w", "raw_h", "filt_x", "filt_y", "filt_w", "filt_h"]
    to_user = np.array([origin, origin, 0.0, 0.0])
    cols = [y_xywh + to_user, est_xywh + to_user]
    if gt is not None:
        summary.update(scores(y_xywh, est_xywh, truth))
        header += ["gt_x", "gt_y", "gt_w", "gt_h", "iou_raw", "iou_filt"]
        cols += [truth + to_user, metrics.iou(y_xywh, truth)[:, None], metrics.iou(est_xywh, truth)[:, None]]
    write_csv(out / "frames.csv", header, [[n, *map(float, r)] for n, r in enumerate(np.hstack(cols))])
    write_json(out / "summary.json", summary)
    if not args.no_video:
        print(f"wrote {write_annotated(out, frames, fps, truth, y_xywh, est_xywh)}")
    print({k: summary[k] for k in summary if "auc" in k or k in ("n_frames", "n_missing")})
    return 0


def annotate(frame: np.ndarray, boxes: list[tuple[np.ndarray, tuple[int, int, int]]], n: int) -> np.ndarray:
    img = frame.copy()
    for box, colour in boxes:
        if np.all(np.isfinite(box)):
            x, y, w, h = box
            cv2.rectangle(img, (int(round(x)), int(round(y))), (int(round(x + w)), int(round(y + h))), colour, 1)
    cv2.putText(img, str(n), (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def write_annotated(out: Path, frames, fps: float, truth: np.ndarray, raw: np.ndarray, est: np.ndarray) -> Path:
    """``video.mp4`` (mp4v); if OpenCV has no MP4 writer, ``strip.png`` of 8 evenly spaced frames."""
    T = len(raw)
    path = out / "video.mp4"

    def write(tmp: Path) -> None:
        writer = None
        for n, frame in enumerate(tqdm(frames, total=T, desc="annotate", unit="frame")):
            if n >= T:
                break
            img = annotate(frame, [(truth[n], _GREEN), (raw[n], _RED), (est[n], _BLUE)], n)
            if writer is None:
                writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter.fourcc(*"mp4v"), fps, img.shape[1::-1])
                if not writer.isOpened():
                    raise OSError("no MP4 writer")
            writer.write(img)
        cast(cv2.VideoWriter, writer).release()  # opened at the first of the T >= 1 frames

    try:
        atomic_write(path, write)
        return path
    except OSError:
        picks, strip = set(np.linspace(0, T - 1, 8).astype(int).tolist()), []
        for n, frame in enumerate(frames):
            if n in picks:
                strip.append(annotate(frame, [(truth[n], _GREEN), (raw[n], _RED), (est[n], _BLUE)], n))
        png = out / "strip.png"
        atomic_write(png, lambda p: cv2.imwrite(str(p), np.concatenate(strip, axis=1)))
        return png

