"""Filter benchmark: batched back ends against per-step / per-point references, measured in the same run.

    python scripts/bench_filters.py [--tracks 256] [--frames 1000] [--ref-tracks 256] [--iter-tracks 4]

Data: the seed 000 two-state set-up (σ_w = 50, σ_ξ = 4, τ = 0.05, ψ = 0.6), ``--tracks`` scalar tracks of
``--frames`` frames. Prints

1. batched ``kf`` vs filterpy's ``KalmanFilter`` predict/update loop (same F, H, Q = σ_w² B Bᵀ, R = σ_v²,
   x0, P0) on ``--ref-tracks`` tracks (default: all), ratio of frame-update rates and max |Δ|;
2. ``ufir`` at N = 160 (kernel form) vs the iterative per-point Algorithm 2 (:func:`filters.ufir.ufir_iterative`)
   run on ``--iter-tracks`` tracks (it costs ~N 2×2 steps per output point; its rate is per point, so the
   ratio does not depend on how many tracks it runs on), ratio of rates and max |Δ| on those tracks;
3. frame-updates/s (tracks × frames / s) of every back end on all tracks.

Timings are the minimum over ``--repeat`` runs (the machine is shared; the minimum is the least disturbed).
Speed is shown here as ratios against a peer measured in the same run, never asserted in unit tests.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

import filters
from envs.simulate import PRESETS, simulate
from filters.ufir import ufir_iterative


def best_time(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


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


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tracks", type=int, default=256)
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--ref-tracks", type=int, default=None, help="tracks for the filterpy loop (default: all)")
    ap.add_argument("--iter-tracks", type=int, default=4, help="tracks for the iterative UFIR reference")
    ap.add_argument("--horizon", type=int, default=160)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    for name in ("tracks", "frames", "iter_tracks", "horizon", "repeat"):
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be >= 1")
    ref_tracks = args.tracks if args.ref_tracks is None else min(args.ref_tracks, args.tracks)

    scenario = replace(PRESETS["seed000_two_state"], psi=0.6, n_frames=args.frames)
    track = simulate(scenario, np.random.default_rng(args.seed), n_tracks=args.tracks)
    y = track.y  # (B, T, 1)
    model = filters.constant_velocity(scenario.tau)
    sw, sv = scenario.sigma_w, scenario.sigma_xi
    x0, P0 = np.array([1.0, 1.0]), np.diag([sv**2, (10 * sv / scenario.tau) ** 2])
    n_updates = y.shape[0] * y.shape[1]
    print(f"data: {args.tracks} tracks x {args.frames} frames (seed 000 set-up, psi=0.6), seed {args.seed}")

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
    t_iter, x_iter = best_time(lambda: np.stack([ufir_iterative(y[b, :, 0], model.F, model.H, N) for b in range(k)]), 1)
    rate_fast, rate_iter = n_updates / t_fast, k * args.frames / t_iter
    diff = np.max(np.abs(x_fast[:k] - x_iter))
    print(f"[2] ufir N={N} kernel: {rate_fast:,.0f} points/s; iterative Algorithm 2 ({k} tracks): "
          f"{rate_iter:,.0f}/s; ratio {rate_fast / rate_iter:,.0f}x (target >= 10,000x); max |dx| = {diff:.2e}")

    print(f"\n[3] frame-updates/s on {args.tracks} x {args.frames} (min of {args.repeat}):")
    params = {"kf": dict(sigma_w=sw, sigma_v=sv), "kf_cmn": dict(sigma_w=sw, sigma_v=sv, psi=0.6),
              "ufir": dict(horizon=N), "ufir_cmn": dict(horizon=N, psi=0.6),
              "ofir": dict(horizon=N, sigma_w=sw, sigma_v=sv), "oufir": dict(horizon=N, sigma_w=sw, sigma_v=sv),
              "fir": dict(horizon=N, sigma_w=sw, sigma_v=sv), "ukf": dict(sigma_w=sw, sigma_v=sv)}
    for name in filters.NAMES:
        flt = filters.make(name, model, **params[name])
        t, _ = best_time(lambda: flt.run(y), args.repeat)
        print(f"    {name:9s} {n_updates / t:>14,.0f}   ({', '.join(f'{k}={v}' for k, v in params[name].items())})")


if __name__ == "__main__":
    main()
