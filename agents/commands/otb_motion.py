"""Measure OTB-100's ground-truth motion, fit the simulator's "otb" motion model, compare with the simulator.

    python scripts/otb_motion.py --otb-root ../shared/data/otb --out docs [--tracks 300] [--seed 0]

Writes ``otb_motion.json`` (the fitted :class:`bboxtune.envs.data.sim_motion.OTBMotion` parameters and every
statistic) and ``otb_motion.md`` (tables) to ``--out``, atomically. Conventions: 30 frames/s (OTB has no time stamps);
centre (cx, cy) increments divided by the box scale s = √(w h) of the earlier frame (box scales per frame, ÷ τ: per
second); x and y pooled; log w and log h pooled. Only the train split (``bboxtune.envs.data.otb.split``) is fitted;
val and test are reported. Simulated tracks are scored like the ground truth after rounding the true boxes to integers
(OTB boxes are integers), at τ = 1/30 s and 500 frames.
"""

from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import welch

from bboxtune.agents.cli import ArgumentParser, command, existing_dir, int_range, nonnegative_int, out_dir
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.data.otb import OTBDataset, split
from bboxtune.envs.data.scenario_ranges import ScenarioRanges
from bboxtune.envs.data.sim_motion import OTBMotion
from bboxtune.envs.data.simulate import simulate_each

TAU = 1 / 30  # s, OTB frame interval
LAGS = (1, 2, 3, 5, 10, 20, 40)  # frames, autocorrelation table
FIT_LAGS = 60  # frames of the autocovariance the centre model is fitted to
BANDS = ((0.0, 1.0), (1.0, 2.0), (2.0, 4.0), (4.0, 8.0), (8.0, 15.0))  # Hz, acceleration spectrum
WINDOW = 10  # frames each side of a velocity-jump test (1/3 s)
JUMPS = (0.5, 1.0, 2.0)  # box scales/s: velocity-jump thresholds of the manoeuvre count


def increments(box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre increments / s (T − 1, 2) and log-size increments (T − 1, 2) of xywh boxes (NaN where missing)."""
    centre, scale = box[:, :2] + box[:, 2:] / 2, np.sqrt(box[:, 2] * box[:, 3])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.diff(centre, axis=0) / scale[:-1, None], np.diff(np.log(box[:, 2:]), axis=0)


def autocov(d: np.ndarray, lags: int) -> np.ndarray:
    """Mean products d_n d_{n+k} for k = 0 … lags over both columns of ``d`` (not mean-removed; NaN skipped)."""
    out = np.full(lags + 1, np.nan)
    for k in range(min(lags + 1, len(d))):
        prod = (d[k:] * d[:len(d) - k]).ravel()
        prod = prod[np.isfinite(prod)]
        out[k] = prod.mean() if prod.size else np.nan
    return out


def shape_model(theta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Normalised increment autocovariance of the "otb" model plus white annotation noise:
    a e^{−λkτ} + b e^{−kτ/T} + n (2 at k = 0, −1 at k = 1), θ = log (a, λ, b, T, n)."""
    a, lam, b, t, n = np.exp(theta)
    return a * np.exp(-lam * k * TAU) + b * np.exp(-k * TAU / t) + n * np.select([k == 0, k == 1], [2.0, -1.0], 0.0)


def track_stats(boxes: list[np.ndarray]) -> dict:
    """Every motion statistic of a set of xywh tracks (each sequence weighs the same where averaged)."""
    d_all, l_all, a_all, shapes, levels, psd, jumps, seconds, d2 = [], [], [], [], [], [], [], 0.0, []
    for box in boxes:
        d, ell = increments(box)
        d_all.append(d[np.isfinite(d).all(1)])
        l_all.append(ell[np.isfinite(ell).all(1)])
        acc = np.diff(d, axis=0) / TAU**2
        a_all.append(acc[np.isfinite(acc).all(1)])
        g = autocov(d, FIT_LAGS)
        shapes.append(g / g[0])
        levels.append(g[0])
        if len(acc) >= 64 and np.isfinite(acc).all():
            f, p = welch(acc, fs=1 / TAU, nperseg=64, axis=0)
            psd.append([p[(lo <= f) & (f < hi)].mean() for lo, hi in BANDS] / p.mean())
        c = np.cumsum(np.nan_to_num(d), axis=0)
        jump = ((c[2 * WINDOW:] - c[WINDOW:-WINDOW]) - (c[WINDOW:-WINDOW] - c[:-2 * WINDOW])) / (WINDOW * TAU)
        jumps.append(jump)
        seconds += 2 * len(jump) * TAU
        d2.append([np.nanmean((box_x[2 * k:] - 2 * box_x[k:-k] + box_x[:-2 * k]) ** 2) if len(box_x) > 2 * k else np.nan
                   for box_x in [(box[:, :2] + box[:, 2:] / 2) / np.nanmedian(np.sqrt(box[:, 2] * box[:, 3]))]
                   for k in (2, 8, 30, 90)])
    v, a, ell = np.concatenate(d_all) / TAU, np.concatenate(a_all), np.concatenate(l_all)
    jump = np.concatenate([j.ravel() for j in jumps])
    shape = np.nanmean(shapes, axis=0)
    slope = np.diff(np.log(np.nanmean(d2, axis=0))) / np.diff(np.log([2, 8, 30, 90]))
    return {
        "n_tracks": len(boxes),
        "frames": [int(len(b)) for b in boxes],
        "velocity": _distribution(v),
        "acceleration": _distribution(a),
        "velocity_rms_per_track": np.percentile(np.sqrt(levels) / TAU, [10, 50, 90]).tolist(),
        "increment_autocorrelation": {str(k): float(shape[k]) for k in LAGS},
        "shape": shape.tolist(),
        "levels": [float(x) for x in levels],
        "d2_log_slopes": slope.tolist(),  # CV with white acceleration: 3
        "acceleration_band_power": np.mean(psd, axis=0).tolist() if psd else [],
        "jump_kurtosis": float(_kurtosis(jump)),
        "manoeuvres_per_s": {str(t): float(sum(_crossings(np.abs(j) > t) for j in jumps) / seconds) for t in JUMPS},
        "log_size": {**_distribution(ell / TAU), "lag1_autocorrelation": float(np.mean(
            [np.corrcoef(x[1:, i], x[:-1, i])[0, 1] for x in l_all if len(x) > 2 and (x.std(0) > 0).all() for i in (0, 1)]))},
    }


def _distribution(x: np.ndarray) -> dict:
    ax = np.abs(x)
    return {"std": float(x.std()), "p50_abs": float(np.percentile(ax, 50)), "p90_abs": float(np.percentile(ax, 90)),
            "p99_abs": float(np.percentile(ax, 99)), "kurtosis": float(_kurtosis(x)), "zero_share": float((x == 0).mean())}


def _kurtosis(x: np.ndarray) -> float:
    x = x - x.mean()
    return float((x**4).mean() / (x**2).mean() ** 2)


def _crossings(above: np.ndarray) -> int:
    """Excursions above a threshold: rising edges of ``above`` (T, 2), per column."""
    return int((above[1:] & ~above[:-1]).sum() + above[:1].sum())


def size_rw(box: np.ndarray) -> float:
    """Random-walk std σ_ℓ (1/√s) of log w, log h: (D(30) − D(1)) / (29 τ) from the structure function
    D(k) = mean (ℓ_{n+k} − ℓ_n)², the noise floor cancelling; NaN when it does not grow (constant size)."""
    ell = np.log(box[:, 2:])
    if len(ell) <= 30:
        return float("nan")
    dk = [np.nanmean((ell[k:] - ell[:-k]) ** 2) for k in (1, 30)]
    growth = (dk[1] - dk[0]) / (29 * TAU)
    return float(np.sqrt(growth)) if growth > 0 else float("nan")


def fit(boxes: list[np.ndarray]) -> tuple[OTBMotion, dict]:
    """The "otb" model fitted to the train split's ground truth: the centre autocovariance shape (equal
    weight per sequence), the per-sequence velocity level (noise share removed) and σ_ℓ."""
    stats = track_stats(boxes)
    k, shape = np.arange(FIT_LAGS + 1), np.array(stats["shape"])
    theta0 = np.log([0.3, 3.0, 0.5, 0.07, 0.1])
    theta = least_squares(lambda th: (shape_model(th, k) - shape) / np.sqrt(1 + k), theta0).x
    a, lam, b, t, n = np.exp(theta)
    motion_share = (a + b) / (a + b + 2 * n)
    level = np.log(np.sqrt(np.array(stats["levels"]) * motion_share) / TAU)
    sizes = np.array([size_rw(box) for box in boxes])
    grows = np.isfinite(sizes)
    motion = OTBMotion(switch_rate=float(lam), cruise_share=float(a / (a + b)), jitter_time=float(t),
                       level_log_mean=float(level.mean()), level_log_std=float(level.std()),
                       size_log_mean=float(np.log(sizes[grows]).mean()), size_log_std=float(np.log(sizes[grows]).std()))
    extra = {"noise_share_of_increment_variance": float(2 * n / (a + b + 2 * n)),
             "annotation_noise_rel": float(np.sqrt(n * np.median(stats["levels"]) / (a + b + 2 * n))),
             "sequences_with_constant_size_trend": int((~grows).sum()), "fit_rms": float(np.sqrt(np.mean(
                 (shape_model(theta, k) - shape) ** 2)))}
    return motion, extra


def simulated(motion: str, n_tracks: int, seed: int) -> list[np.ndarray]:
    """Integer-rounded xywh truth of ``n_tracks`` simulated 500-frame tracks at τ = 1/30 s (EnvConfig's
    default scenario ranges otherwise), seeds ``seed`` …"""
    ranges = ScenarioRanges(tau=(TAU, TAU), n_frames=(500, 500), motion=motion)
    rngs = [np.random.default_rng(seed + i) for i in range(n_tracks)]
    tracks = simulate_each([ranges.sample(rng) for rng in rngs], rngs)
    return [np.round(np.concatenate([t.truth[:, :2] - t.truth[:, 2:] / 2, t.truth[:, 2:]], axis=1)) for t in tracks]


def _row(name: str, values: list, fmt: str = "{:.3g}") -> str:
    return "| " + " | ".join([name, *(fmt.format(v) for v in values)]) + " |"


def report(result: dict) -> str:
    """The markdown tables of ``result`` (what main writes to otb_motion.json)."""
    stats, fitted, names = result["stats"], result["fitted"], list(result["stats"])
    head = "| statistic | " + " | ".join(names) + " |\n|---|" + "---|" * len(names)
    rows = [_row("tracks", [stats[n]["n_tracks"] for n in names], "{}")]
    for q in (0, 50, 100):
        rows.append(_row(f"frames p{q}", [np.percentile(stats[n]["frames"], q) for n in names], "{:.0f}"))
    for what, unit in (("velocity", "box scales/s"), ("acceleration", "box scales/s²"), ("log_size", "log-size rate, 1/s")):
        for key in ("std", "p50_abs", "p90_abs", "p99_abs", "kurtosis", "zero_share"):
            rows.append(_row(f"{what} {key} ({unit})", [stats[n][what][key] for n in names]))
    rows.append(_row("log-size increment lag-1 autocorrelation", [stats[n]["log_size"]["lag1_autocorrelation"] for n in names]))
    for i, q in enumerate((10, 50, 90)):
        rows.append(_row(f"rms centre velocity per track, p{q} (box scales/s)",
                         [stats[n]["velocity_rms_per_track"][i] for n in names]))
    for k in LAGS:
        rows.append(_row(f"centre increment autocorrelation, lag {k}",
                         [stats[n]["increment_autocorrelation"][str(k)] for n in names]))
    for i, (lo, hi) in enumerate(((2, 8), (8, 30), (30, 90))):
        rows.append(_row(f"log-log slope of D2(k), k = {lo}…{hi} (CV: 3)", [stats[n]["d2_log_slopes"][i] for n in names]))
    for i, (f_lo, f_hi) in enumerate(BANDS):
        rows.append(_row(f"acceleration power {f_lo:g}–{f_hi:g} Hz / mean (white: 1)",
                         [stats[n]["acceleration_band_power"][i] for n in names]))
    for t in JUMPS:
        rows.append(_row(f"manoeuvres/s: velocity jumps > {t:g} box scales/s",
                         [stats[n]["manoeuvres_per_s"][str(t)] for n in names]))
    rows.append(_row(f"kurtosis of the {WINDOW}-frame velocity jumps (Gaussian: 3)", [stats[n]["jump_kurtosis"] for n in names]))
    tr, cv, sim = stats["otb_train"], stats["sim_cv"], stats["sim_otb"]
    findings = (
        "## Findings\n\n"
        f"* Velocity: OTB's centres move {tr['velocity_rms_per_track'][1]:.2g} box scales/s (median track rms; "
        f"p10–p90 {tr['velocity_rms_per_track'][0]:.2g}–{tr['velocity_rms_per_track'][2]:.2g}); the \"cv\" default "
        f"scenario moves {cv['velocity_rms_per_track'][1]:.2g} (absolute σ_w 1–100 px/s² on 20–200 px boxes): about a "
        "decade too slow, and its spread across tracks is not scale-relative.\n"
        "* CV with white acceleration is not adequate: the acceleration spectrum is far from flat (0–1 Hz holds "
        f"{tr['acceleration_band_power'][0]:.2g} of the mean power, \"cv\" {cv['acceleration_band_power'][0]:.2g}) and "
        f"D2(k) grows with slope {tr['d2_log_slopes'][0]:.2g}/{tr['d2_log_slopes'][1]:.2g}/{tr['d2_log_slopes'][2]:.2g} "
        "(CV: 3): velocity decorrelates within a fraction of a second "
        f"(increment autocorrelation {tr['increment_autocorrelation']['10']:.2g} at 10 frames; \"cv\" "
        f"{cv['increment_autocorrelation']['10']:.2g}).\n"
        f"* Manoeuvres: velocity jumps > 1 box scale/s over {WINDOW}-frame windows occur "
        f"{tr['manoeuvres_per_s']['1.0']:.2g} times per second on OTB, {cv['manoeuvres_per_s']['1.0']:.2g} in \"cv\", "
        f"{sim['manoeuvres_per_s']['1.0']:.2g} in \"otb\".\n"
        f"* Sizes: log w, log h change at {tr['log_size']['std']:.2g}/s rms on OTB (lag-1 autocorrelation "
        f"{tr['log_size']['lag1_autocorrelation']:.2g}: annotation noise), {cv['log_size']['std']:.2g}/s in \"cv\"; "
        f"{tr['log_size']['zero_share']:.0%} of OTB frames keep the size.\n"
        f"* Annotation floor: boxes are integers (centres on a 0.5 px grid); the fit attributes "
        f"{result['fit']['noise_share_of_increment_variance']:.0%} of the centre increment variance to white "
        f"annotation noise ({result['fit']['annotation_noise_rel']:.2g} box scales rms at the median track).\n"
        f"* Not reproduced by \"otb\": OTB positions are bounded (D2 slope {tr['d2_log_slopes'][2]:.2g} at 1–3 s, "
        f"\"otb\" {sim['d2_log_slopes'][2]:.2g}), track lengths (OTB {min(tr['frames'])}–{max(tr['frames'])} frames; "
        "the env keeps track_length), the heaviest tails (velocity p90 across tracks).\n\n")
    fit_rows = "\n".join(f"| `{k}` | {v:.4g} |" for k, v in {**fitted, **result["fit"]}.items())
    return (f"# OTB-100 ground-truth motion (generated by `{result['command']}`)\n\n" + findings
            + f"## Fitted \"otb\" motion (train split)\n\n| parameter | value |\n|---|---|\n{fit_rows}\n\n"
            f"## Statistics (τ = {TAU:.4g} s; sim: integer-rounded truth)\n\n{head}\n" + "\n".join(rows) + "\n")


DEFAULT_TRACKS = 300  # simulated tracks per motion model


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="otb_motion.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--otb-root", type=existing_dir, default=None, help="OTB data folder (default: $OTB_ROOT)")
    parser.add_argument("--out", type=out_dir, required=True,
                        help="folder for otb_motion.json and otb_motion.md (created if missing; these two files are "
                             "replaced, each atomically)")
    parser.add_argument("--tracks", type=int_range(1, 100_000), default=DEFAULT_TRACKS,
                        help="simulated tracks per motion model (default 300)")
    parser.add_argument("--seed", type=nonnegative_int, default=0, help="first noise seed of the simulated tracks")
    args = parser.parse_args(argv)
    try:
        dataset = OTBDataset(args.otb_root)
        parts = split(dataset.names)
        gt = {part: [dataset.groundtruth(n) for n in names] for part, names in parts.items()}
        motion, extra = fit(gt["train"])
        stats = {f"otb_{part}": track_stats(boxes) for part, boxes in gt.items()}
        for name in ("cv", "otb"):
            stats[f"sim_{name}"] = track_stats(simulated(name, args.tracks, args.seed))
    except (ValueError, OSError) as err:
        parser.error(f"--otb-root: {err}")
    result = {"fitted": asdict(motion), "fit": extra, "stats": stats, "tau": TAU,
              "command": " ".join(["python scripts/otb_motion.py --otb-root $OTB_ROOT", f"--out {args.out}",  # no local root
                                   *([f"--tracks {args.tracks}"] if args.tracks != DEFAULT_TRACKS else []),
                                   *([f"--seed {args.seed}"] if args.seed else [])])}
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "otb_motion.json", json.dumps(result, indent=1) + "\n")
    write_text_atomic(out / "otb_motion.md", report(result))
    print(json.dumps(result["fitted"]))
    return 0

