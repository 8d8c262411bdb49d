"""Filter benchmark: batched back ends against per-step / per-point references, measured in the same run.

    python scripts/bench_filters.py [--tracks 256] [--frames 1000] [--ref-tracks 256] [--iter-tracks 4]
                                    [--wide-tracks 20000] [--wide-frames 500] [--missing 0.05]
                                    [--long-frames 1000000] [--sections reference backends wide long]

Data of sections 1–3: the [Shmaliy-CMN] two-state set-up (σ_w = 50, σ_ξ = 4, τ = 0.05, ψ = 0.6), ``--tracks`` scalar
tracks of ``--frames`` frames. Prints

1. batched ``kf`` vs filterpy's ``KalmanFilter`` predict/update loop (same F, H, Q = σ_w² B Bᵀ, R = σ_v²,
   x0, P0) on ``--ref-tracks`` tracks (default: all), ratio of frame-update rates and max |Δ|;
2. ``ufir`` at N = 160 (kernel form) vs the iterative per-point Algorithm 2 (:func:`bboxtune.filters.ufir.ufir_iterative`)
   run on ``--iter-tracks`` tracks (it costs ~N 2×2 steps per output point; its rate is per point, so the
   ratio does not depend on how many tracks it runs on), ratio of rates and max |Δ| on those tracks;
3. frame-updates/s (tracks × frames / s) of every back end on all tracks, and of the peer box filters
   (``bboxtune.filters.PEER_NAMES``) beside ``kf`` on as many box tracks (those of section 4, ``--missing`` of frames missing);
4. wide batches: every back end on ``--wide-tracks`` box tracks (cx, cy, w, h; τ = 1/30, random walks around
   200 px) of ``--wide-frames`` frames, without missing frames and with a share ``--missing`` of frames missing
   (whole boxes, independently per frame): seconds (wall and CPU) and peak RSS of each, and the ratios
   with gaps / without;
5. a long track: ``ukf`` on one box track of ``--long-frames`` frames, beside ``kf`` with the same σ, without
   and with missing frames: seconds, peak RSS, ratios ukf / kf.

Timings of sections 1–3 are the minimum over ``--repeat`` runs (the machine is shared; the minimum is the least
disturbed). Each case of sections 4–5 runs once in a fresh subprocess, so its peak RSS (``ru_maxrss``: the data,
the result and the filter's working memory, plus ~60–100 MB of interpreter and libraries, shown as "before") is
its own. Speed is shown as ratios against a peer measured in the same run, never asserted in unit tests.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import TypeVar, cast

import numpy as np

from bboxtune import filters
from bboxtune.agents.cli import ArgumentParser, HelpFormatter, command, float_range, nonnegative_int, positive_int
from bboxtune.envs.data.simulate import PRESETS, simulate
from bboxtune.filters.ufir import ufir_iterative

SECTIONS = ("reference", "backends", "wide", "long")
SIGMA_W, SIGMA_V, PSI = 50.0, 4.0, 0.6  # every section: the [Shmaliy-CMN] set-up (px/s², px, –)
TAU = 1 / 30  # s, the box tracks of sections 4–5
Result = TypeVar("Result")


def best_time(fn: Callable[[], Result], repeat: int) -> tuple[float, Result]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, cast(Result, out)  # repeat >= 1: fn ran


def filterpy_loop(y: np.ndarray, model: filters.StateSpaceModel, sigma_w: float, sigma_v: float,
                  x0: np.ndarray, P0: np.ndarray) -> np.ndarray:
    from filterpy.kalman import KalmanFilter

    out = np.empty((*y.shape[:2], model.K))
    for b in range(y.shape[0]):  # the reference is a per-track, per-step loop by construction
        kf = KalmanFilter(dim_x=model.K, dim_z=model.M)
        kf.F, kf.H = model.F.copy(), model.H.copy()
        kf.Q = sigma_w**2 * model.B @ model.B.T
        kf.R = sigma_v**2 * np.eye(model.M)
        kf.x, kf.P = x0.copy(), P0.copy()
        for t in range(y.shape[1]):
            kf.predict()
            kf.update(y[b, t])
            out[b, t] = kf.x
    return out


def backend_params(name: str, horizon: int) -> dict[str, float]:
    """The parameters every section runs back end ``name`` with."""
    sigma = {"sigma_w": SIGMA_W, "sigma_v": SIGMA_V}
    params: dict[str, dict[str, float]] = {
        "kf": sigma, "kf_cmn": {**sigma, "psi": PSI}, "ufir": {"horizon": horizon},
        "ufir_cmn": {"horizon": horizon, "psi": PSI}, "ofir": {**sigma, "horizon": horizon},
        "oufir": {**sigma, "horizon": horizon}, "fir": {**sigma, "horizon": horizon}, "ukf": sigma}
    return params[name]


def box_tracks(n_tracks: int, n_frames: int, missing: float, seed: int) -> np.ndarray:
    """Random-walk boxes (n_tracks, n_frames, 4) around 200 px, a share ``missing`` of frames NaN; built in
    blocks of tracks so that no temporary is as large as the result."""
    rng = np.random.default_rng(seed)
    y = np.empty((n_tracks, n_frames, 4))
    for first in range(0, n_tracks, 1024):
        part = y[first:first + 1024]
        np.cumsum(rng.normal(0.0, 2.0, part.shape), axis=1, out=part)
        part += 200.0
        part[rng.random(part.shape[:2]) < missing] = np.nan
    return y


def run_case(case: dict) -> dict:
    """One case of sections 4–5 (in the subprocess): build the data, run the filter once; time and peak RSS."""
    y = box_tracks(case["tracks"], case["frames"], case["missing"], case["seed"])
    flt = filters.make(case["backend"], filters.constant_velocity(TAU, ndim=4),
                       **backend_params(case["backend"], case["horizon"]))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0, c0 = time.perf_counter(), time.process_time()
    out = flt.run(y)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
    finite = bool(np.isfinite(out[:, -1]).all())
    return {"wall": wall, "cpu": cpu, "before_mb": before, "peak_mb": peak, "finite_at_end": finite}


CHILD = f"from {__name__} import main; raise SystemExit(main())"  # python -c CHILD --child CASE: one case


def measure(case: dict) -> dict:
    """:func:`run_case` in a fresh interpreter (clean peak RSS)."""
    done = subprocess.run([sys.executable, "-c", CHILD, "--child", json.dumps(case)],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"case {case} failed: {done.stderr.strip().splitlines()[-1:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def ratio(a: float, b: float) -> str:
    return f"x{a / b:.2f}" if b > 0 else "n/a"


def show(label: str, r: dict) -> str:
    return (f"{label} {r['wall']:7.2f} s (cpu {r['cpu']:7.2f} s), peak RSS {r['peak_mb']:6.0f} MB "
            f"(before {r['before_mb']:4.0f} MB)")


def wide_section(args: argparse.Namespace) -> None:
    print(f"\n[4] wide batches: {args.wide_tracks} box tracks x {args.wide_frames} frames, N = {args.wide_horizon}; "
          f"without / with {args.missing:.0%} of frames missing")
    for name in args.backends:
        base = {"backend": name, "tracks": args.wide_tracks, "frames": args.wide_frames,
                "horizon": args.wide_horizon, "seed": args.seed}
        free, gaps = measure({**base, "missing": 0.0}), measure({**base, "missing": args.missing})
        print(f"    {name:9s}{show(' no gaps:', free)}")
        print(f"    {'':9s}{show('    gaps:', gaps)}   gaps/no gaps: time {ratio(gaps['wall'], free['wall'])} "
              f"(cpu {ratio(gaps['cpu'], free['cpu'])}), peak {ratio(gaps['peak_mb'], free['peak_mb'])}")


def long_section(args: argparse.Namespace) -> None:
    print(f"\n[5] one box track of {args.long_frames:,} frames: ukf beside kf (same sigma), "
          f"without / with {args.missing:.0%} of frames missing")
    for missing in (0.0, args.missing):
        base = {"tracks": 1, "frames": args.long_frames, "horizon": args.wide_horizon, "seed": args.seed,
                "missing": missing}
        ukf, kf = measure({**base, "backend": "ukf"}), measure({**base, "backend": "kf"})
        print(f"    missing {missing:.0%}: {show('ukf', ukf)}")
        print(f"    {'':13s}{show('kf ', kf)}   ukf/kf: time {ratio(ukf['wall'], kf['wall'])} "
              f"(cpu {ratio(ukf['cpu'], kf['cpu'])}); ukf {args.long_frames / max(ukf['wall'], 1e-9):,.0f} frames/s")


def speed_sections(args: argparse.Namespace) -> None:
    ref_tracks = args.tracks if args.ref_tracks is None else min(args.ref_tracks, args.tracks)
    scenario = replace(PRESETS["seed000_two_state"], psi=0.6, n_frames=args.frames)
    track = simulate(scenario, np.random.default_rng(args.seed), n_tracks=args.tracks)
    y = track.y  # (B, T, 1)
    model = filters.constant_velocity(scenario.tau)
    sw, sv = scenario.sigma_w, scenario.sigma_xi
    x0, P0 = np.array([1.0, 1.0]), np.diag([sv**2, (10 * sv / scenario.tau) ** 2])
    n_updates = y.shape[0] * y.shape[1]
    print(f"data: {args.tracks} tracks x {args.frames} frames ([Shmaliy-CMN] set-up, psi=0.6), seed {args.seed}")

    if "reference" in args.sections:
        kf = filters.make("kf", model, sigma_w=sw, sigma_v=sv, x0=x0, P0=P0)
        t_kf, x_kf = best_time(lambda: kf.run(y), args.repeat)
        t_ref, x_ref = best_time(lambda: filterpy_loop(y[:ref_tracks], model, sw, sv, x0, P0), 1)
        rate_kf, rate_ref = n_updates / t_kf, ref_tracks * args.frames / t_ref
        diff = np.max(np.abs(x_kf[:ref_tracks] - x_ref))
        print(f"\n[1] kf batched: {rate_kf:,.0f} frame-updates/s; filterpy loop ({ref_tracks} tracks): "
              f"{rate_ref:,.0f}/s; ratio {rate_kf / rate_ref:,.0f}x (target >= 300x); max |dx| = {diff:.2e}")

        N = args.horizon
        ufir = filters.make("ufir", model, horizon=N)
        t_fast, x_fast = best_time(lambda: ufir.run(y), args.repeat)
        k = min(args.iter_tracks, args.tracks)
        t_iter, x_iter = best_time(
            lambda: np.stack([ufir_iterative(y[b, :, 0], model.F, model.H, N) for b in range(k)]), 1)
        rate_fast, rate_iter = n_updates / t_fast, k * args.frames / t_iter
        diff = np.max(np.abs(x_fast[:k] - x_iter))
        print(f"[2] ufir N={N} kernel: {rate_fast:,.0f} points/s; iterative Algorithm 2 ({k} tracks): "
              f"{rate_iter:,.0f}/s; ratio {rate_fast / rate_iter:,.0f}x (target >= 10,000x); max |dx| = {diff:.2e}")

    if "backends" in args.sections:
        print(f"\n[3] frame-updates/s on {args.tracks} x {args.frames} (min of {args.repeat}):")
        for name in filters.NAMES:
            params = backend_params(name, args.horizon)  # σ_w, σ_v, ψ of the [Shmaliy-CMN] set-up
            flt = filters.make(name, model, **params)
            t, _ = best_time(partial(flt.run, y), args.repeat)
            print(f"    {name:9s} {n_updates / t:>14,.0f}   ({', '.join(f'{k}={v}' for k, v in params.items())})")
        boxes = box_tracks(args.tracks, args.frames, args.missing, args.seed)
        boxes[..., 2:] = 20.0 + np.abs(boxes[..., 2:] - 200.0)  # sizes >= 20 px: the peers need w, h > 0
        print(f"    box tracks ({args.tracks} x {args.frames}, {args.missing:.0%} of frames missing): the peer filters "
              "(bboxtune.filters.PEER_NAMES, published defaults) beside kf, box frame-updates/s:")
        for name in ("kf", *filters.PEER_NAMES):
            params = backend_params(name, args.horizon) if name == "kf" else {}
            flt = filters.make(name, filters.constant_velocity(TAU, ndim=4), **params)
            t, _ = best_time(partial(flt.run, boxes), args.repeat)
            print(f"    {name:12s} {n_updates / t:>14,.0f}")


@command
def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(prog="bench_filters.py", description=__doc__, formatter_class=HelpFormatter)
    ap.add_argument("--tracks", type=positive_int, default=256, help="tracks of sections 1–3")
    ap.add_argument("--frames", type=positive_int, default=1000, help="frames per track, sections 1–3")
    ap.add_argument("--ref-tracks", type=positive_int, default=None, help="tracks for the filterpy loop (default: all)")
    ap.add_argument("--iter-tracks", type=positive_int, default=4, help="tracks for the iterative UFIR reference")
    ap.add_argument("--horizon", type=positive_int, default=160, help="FIR horizon N of sections 1–3 (>= 2)")
    ap.add_argument("--repeat", type=positive_int, default=5, help="timed runs per measurement, sections 1–3")
    ap.add_argument("--wide-tracks", type=positive_int, default=20_000, help="box tracks of section 4")
    ap.add_argument("--wide-frames", type=positive_int, default=500, help="frames per track, section 4")
    ap.add_argument("--wide-horizon", type=positive_int, default=60, help="FIR horizon N of sections 4–5 (>= 2)")
    ap.add_argument("--missing", type=float_range(0.0, 0.9), default=0.05,
                    help="share of missing frames in sections 4–5")
    ap.add_argument("--long-frames", type=positive_int, default=1_000_000, help="frames of the track of section 5")
    ap.add_argument("--backends", nargs="+", choices=filters.NAMES, default=list(filters.NAMES),
                    help="back ends of section 4")
    ap.add_argument("--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS), help="what to run")
    ap.add_argument("--seed", type=nonnegative_int, default=0)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:  # one case of sections 4–5, in its own process (see measure)
        print(json.dumps(run_case(json.loads(args.child))))
        return 0
    for flag in ("horizon", "wide_horizon"):
        if getattr(args, flag) < 2:
            ap.error(f"argument --{flag.replace('_', '-')}: invalid value {getattr(args, flag)}; allowed: integers >= 2")
    if {"reference", "backends"} & set(args.sections):
        speed_sections(args)
    if "wide" in args.sections:
        wide_section(args)
    if "long" in args.sections:
        long_section(args)
    return 0
