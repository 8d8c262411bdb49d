"""Camera-motion compensation on synthetic videos with a moving camera: RMSE with and without it.

    python scripts/video_camera.py                                   # 12 videos, template detector
    python scripts/video_camera.py --detector orb --n-videos 20 --out runs/video_camera

Videos: generator seeds 3 000 000 + i (none in the train/val/test splits), every one with camera motion
(pan + shake, 5–25 px). The detector measures boxes; the background shift per frame is estimated from the
frames (:func:`bboxtune.envs.video.camera.background_shift`). Compared at the same filter parameters — the fixed rule's
σ_v, σ_w (nominal of the detector) scaled by ``--smoothing`` factors on σ_v (more smoothing to the right):

* ``kf`` vs ``kf+input``: KF on the raw boxes vs with the camera velocity as known input ([Raj-UKF] eq. 18);
* ``ukf`` vs ``ukf8``: UKF vs the camera-augmented UKF of [Raj-UKF] eq. 17 fed the measured background velocity;
* ``kf+true``: camera-velocity input from the generator's true camera path (how much the estimate loses).

RMSE: centre (cx, cy) error in px over all frames. Writes ``results.csv``, ``summary.json`` and
``camera.png`` (mean RMSE vs smoothing; per-video RMSE at the rule; the cx error over time of the video with
the strongest camera motion at ``--example-smoothing``) into ``--out``, created if missing; in an existing
folder these three files are replaced and every other file is left alone. The command line is checked before
any work: a bad value exits 2 with one line naming the flag, and nothing is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bboxtune import filters  # noqa: E402
from bboxtune.agents.cli import ArgumentParser, argument_errors, command, nonnegative_int, out_dir, positive_float, positive_int  # noqa: E402
from bboxtune.agents.evaluation.stats import paired_mean_ci  # noqa: E402
from bboxtune.agents.evaluation.video_tables import write_csv, write_json  # noqa: E402
from bboxtune.envs.data.atomic_files import atomic_write  # noqa: E402
from bboxtune.envs.episodes.config import EnvConfig  # noqa: E402
from bboxtune.envs.episodes.video_source import VideoSettings, VideoSource  # noqa: E402
from bboxtune.envs.video.camera import UKF_CAMERA, background_shift, run_compensated  # noqa: E402
from bboxtune.envs.video.detectors import DETECTORS, detect_video, make_detector  # noqa: E402
from bboxtune.envs.video.synthetic import VideoRanges, synthetic_video  # noqa: E402

SEED_OFFSET = 3_000_000
METHODS = ("kf", "kf+input", "ukf", "ukf8", "kf+true")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = ArgumentParser(prog="video_camera.py", description=__doc__.split("\n\n")[0],
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--n-videos", type=positive_int, default=12, help="videos (generator seeds 3 000 000 + i)")
    p.add_argument("--frames", type=positive_int, default=200, help="frames per video (the env's limits)")
    p.add_argument("--detector", default="template", choices=DETECTORS)
    p.add_argument("--smoothing", type=positive_float, nargs="+", default=[0.3, 1.0, 3.0, 10.0, 30.0],
                   help="factors on the rule's σ_v (1 = the rule)")
    p.add_argument("--sigma-c", type=positive_float, default=UKF_CAMERA["sigma_c"],
                   help="ukf8: camera acceleration noise std, px/s²")
    p.add_argument("--sigma-u", type=positive_float, default=UKF_CAMERA["sigma_u"],
                   help="ukf8: std of the measured background velocity, px/s")
    p.add_argument("--example-smoothing", type=positive_float, default=10.0,
                   help="σ_v factor of the example-error panel")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the bootstrap intervals")
    p.add_argument("--out", type=out_dir, default="runs/video_camera",
                   help="output folder (created if missing; its three result files are replaced)")
    args = p.parse_args(argv)
    with argument_errors(p, "--frames"):  # the env's and the generator's own checks, before any work
        EnvConfig(track_length=args.frames)
        VideoRanges(n_frames=args.frames).sample(np.random.default_rng(0))
    return args


def centre_rmse(est: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((est[:, :2] - truth[:, :2]) ** 2, axis=1))))


def compare(seed: int, args: argparse.Namespace, ranges: VideoRanges) -> dict:
    """RMSE of every method × smoothing factor on video ``seed`` (plus the tracks of the rule setting)."""
    video = synthetic_video(seed, ranges)
    frames = list(video)
    y_xywh = detect_video(make_detector(args.detector), frames, video.boxes[0])
    shift = background_shift(frames)
    true_shift = -np.diff(video.camera, axis=0, prepend=video.camera[:1])
    source = VideoSource(EnvConfig(track_length=args.frames), VideoSettings(detector=args.detector))
    ep = source.episode({"truth": video.boxes, "y": y_xywh, "tau": np.float64(video.tau)}, meta={"seed": seed})
    model = filters.constant_velocity(ep.tau, ndim=4)
    out: dict[str, Any] = {"seed": seed, "camera_motion": video.scenario.camera_motion, "rmse": {}, "tracks": {}}
    for k in args.smoothing:
        p = {"sigma_w": ep.nominal.sigma_w, "sigma_v": k * ep.nominal.sigma_v}
        ukf8 = {**p, "sigma_c": args.sigma_c, "sigma_u": args.sigma_u}
        est = {
            "kf": filters.make("kf", model, **p).run(ep.y),
            "kf+input": run_compensated("kf", ep.y, shift, ep.tau, **p),
            "ukf": filters.make("ukf", model, **p).run(ep.y),
            "ukf8": run_compensated("ukf", ep.y, shift, ep.tau, **ukf8),
            "kf+true": run_compensated("kf", ep.y, true_shift, ep.tau, **p),
        }
        out["rmse"][k] = {m: centre_rmse(e, ep.truth) for m, e in est.items()}
        if k == args.example_smoothing:
            out["errors"] = {m: est[m][:, 0] - ep.truth[:, 0] for m in ("kf", "kf+input", "ukf", "ukf8")}
    out["shift_error_px"] = float(np.sqrt(np.nanmean((shift - true_shift) ** 2)))
    return out


@command
def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.smoothing = sorted({*args.smoothing, 1.0, args.example_smoothing})
    ranges = VideoRanges(n_frames=args.frames, camera_probability=1.0)
    results = [compare(SEED_OFFSET + i, args, ranges) for i in tqdm(range(args.n_videos), desc="videos")]
    rows = [(r["seed"], k, m, r["rmse"][k][m]) for r in results for k in args.smoothing for m in METHODS]
    out: Path = args.out
    write_csv(out / "results.csv", ("seed", "sigma_v_factor", "method", "centre_rmse"), rows)
    rng = np.random.default_rng(args.seed)
    summary: dict[str, Any] = {"args": {**vars(args), "out": str(out)},
                               "shift_error_px_mean": float(np.mean([r["shift_error_px"] for r in results])),
                               "by_smoothing": {}}
    for k in args.smoothing:
        rm = {m: np.array([r["rmse"][k][m] for r in results]) for m in METHODS}
        entry: dict[str, Any] = {f"{m}_mean": float(v.mean()) for m, v in rm.items()}
        for comp, base in (("kf+input", "kf"), ("ukf8", "ukf")):
            ratio = np.log(rm[comp] / rm[base])
            entry[f"{comp}_vs_{base}_log_ratio"] = float(ratio.mean())
            entry[f"{comp}_vs_{base}_log_ratio_ci95"] = paired_mean_ci(ratio, rng)
            entry[f"{comp}_vs_{base}_wins"] = int((ratio < 0).sum())
        summary["by_smoothing"][str(k)] = entry
    write_json(out / "summary.json", summary)
    figure(out / "camera.png", results, args)
    for k, e in summary["by_smoothing"].items():
        n = len(results)
        print(f"σ_v×{k:>5}: " + "  ".join(f"{m} {e[m + '_mean']:.2f}" for m in METHODS)
              + f"  | kf+input wins {e['kf+input_vs_kf_wins']}/{n}, ukf8 wins {e['ukf8_vs_ukf_wins']}/{n}")
    return 0


def figure(path: Path, results: list[dict], args: argparse.Namespace) -> None:
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    ks = np.array(args.smoothing)
    for m in METHODS:
        ax[0].plot(ks, [np.mean([r["rmse"][k][m] for r in results]) for k in ks], "o-", label=m)
    ax[0].set(xscale="log", xlabel="σ_v / rule σ_v (more smoothing →)", ylabel="centre RMSE, px (mean over videos)",
              title=f"{args.detector}: {len(results)} videos with camera motion")
    ax[0].legend()
    idx = np.arange(len(results))
    for j, m in enumerate(("kf", "kf+input", "ukf", "ukf8")):
        ax[1].bar(idx + 0.2 * (j - 1.5), [r["rmse"][1.0][m] for r in results], 0.2, label=m)
    ax[1].set(xlabel="video", ylabel="centre RMSE at the rule, px", yscale="log", title="per video (rule parameters)")
    ax[1].legend()
    ex = max(results, key=lambda r: r["camera_motion"])
    for m, style in (("kf", "C0-"), ("kf+input", "C1-"), ("ukf", "C2:"), ("ukf8", "C3--")):
        ax[2].plot(ex["errors"][m], style, lw=1.2, label=m)
    ax[2].set(xlabel="frame", ylabel="cx error, px", title=f"seed {ex['seed']} (camera {ex['camera_motion']:.0f} px), "
              f"σ_v × {args.example_smoothing:g}")
    ax[2].legend(fontsize=8)
    fig.tight_layout()
    atomic_write(path, lambda p: fig.savefig(p, dpi=110))
    plt.close(fig)

