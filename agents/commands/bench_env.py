"""Environment benchmark: how fast episodes go through ``gym.make`` + ``step`` and through batched scoring.

    python scripts/bench_env.py [--backend ufir_cmn] [--episodes 1000] [--candidates 256] [--track-length 500]

For ``bboxtune/FilterTune-v0`` (source "sim", 500-frame 4-coordinate box tracks) it prints

1. steps/s through the public API: ``env.reset(); env.step(action)`` on ``gym.make``'s wrapped env (one
   step per episode, so every step includes drawing, simulating and summarising a new track and the
   fixed-rule run it is compared with — prepared in blocks, see ``bboxtune.envs.tune_env``) — target >= 1,000 steps/s;
   and, as ratios to it, [1b] ``env.reset(seed=i); env.step(action)`` with i = 0, 1, … (consecutive seeds: the env
   reads their episodes ahead in blocks) and [1c] the same with scattered seeds (each reseed prepares one episode);
   the timed blocks of [1], [1b] and [1c] alternate, so a change of load hits all three;
2. episodes/s through the batched scoring path ``env.unwrapped.score(actions)`` with ``--candidates``
   distinct actions per call (each candidate is one filtered and scored episode) — target >= 5,000;
3. the cost of a step in runs of the filter alone (one candidate, gains cached), from the same run, as a ratio;
4. env steps/s of the batched vec env (``bboxtune.agents.training.batched.TuneVecEnv``, ``--n-envs`` tracks per step, what
   ``train.py`` trains on; targets >= 10,000 for ufir_cmn, >= 6,000 for kf_cmn), as a ratio to [1] and to
   filterpy's ``KalmanFilter`` loop running the same tracks (``--filterpy-tracks`` of them; tracks/s), with the kernel
   threads it ran on and the minor page faults a step (memory mapped afresh, ``bboxtune.filters.allocator``).

Rates are the best of ``--repeat`` timed blocks (the machine is shared; the best block is the least disturbed), with
the median in parentheses. Every block draws fresh random actions, so no filter gain comes from the cache of an
earlier block (the fixed rule's gains repeat and are cached, as in training). No unit test asserts on time.
"""

from __future__ import annotations

import resource
import time
from typing import TYPE_CHECKING, cast

import gymnasium as gym
import numpy as np

from bboxtune import (
    envs,  # noqa: F401  (registers the environments)
    filters,
)
from bboxtune.agents.cli import ArgumentParser, argument_errors, command, nonnegative_int, positive_int
from bboxtune.agents.commands.bench_filters import filterpy_loop
from bboxtune.agents.training.runs import make_vec
from bboxtune.envs.episodes.actions import BACKENDS
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.scoring import run_positions
from bboxtune.filters.threads import kernel_threads

if TYPE_CHECKING:
    from bboxtune.agents.training.batched import TuneVecEnv
    from bboxtune.envs.episodes.episode import Episode
    from bboxtune.envs.tune_env import FilterTuneEnv


def rates(count: int, fn, repeat: int) -> tuple[float, float]:
    """``count`` / the time of each of ``repeat`` timed calls ``fn(r)``, r = 0 … repeat − 1: (best, median)."""
    seconds = []
    for r in range(repeat):
        t0 = time.perf_counter()
        fn(r)
        seconds.append(time.perf_counter() - t0)
    return count / min(seconds), count / float(np.median(seconds))


def alternating_rates(count: int, fns: list, repeat: int) -> list[tuple[float, float]]:
    """:func:`rates` of each of ``fns``, their timed blocks alternating (r = 0: each fn once, then r = 1, …), so that
    a change of the shared machine's load between blocks hits all of them alike and their ratio stays fair."""
    seconds: list[list[float]] = [[] for _ in fns]
    for r in range(repeat):
        for fn, times in zip(fns, seconds, strict=True):
            t0 = time.perf_counter()
            fn(r)
            times.append(time.perf_counter() - t0)
    return [(count / min(times), count / float(np.median(times))) for times in seconds]


@command
def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(prog="bench_env.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", default="ufir_cmn", choices=BACKENDS)
    ap.add_argument("--episodes", type=positive_int, default=1000, help="steps per timed block")
    ap.add_argument("--candidates", type=positive_int, default=256, help="actions per score() call")
    ap.add_argument("--calls", type=positive_int, default=10, help="score() calls per timed block")
    ap.add_argument("--track-length", type=positive_int, default=500, help="frames per track (the env's limits)")
    ap.add_argument("--repeat", type=positive_int, default=5, help="timed blocks per measurement")
    ap.add_argument("--n-envs", type=positive_int, default=256, help="envs of the batched vec env [4]")
    ap.add_argument("--vec-steps", type=positive_int, default=8, help="batched vec env steps per timed block [4]")
    ap.add_argument("--filterpy-tracks", type=positive_int, default=16, help="tracks filterpy filters per timed block [4]")
    ap.add_argument("--seed", type=nonnegative_int, default=0)
    args = ap.parse_args(argv)
    with argument_errors(ap, "--track-length"):
        EnvConfig(backend=args.backend, track_length=args.track_length)  # the env's own checks, before any work

    env = gym.make("bboxtune/FilterTune-v0", backend=args.backend, track_length=args.track_length)
    env.reset(seed=args.seed)
    env.action_space.seed(args.seed)
    # fresh actions in every timed block: no filter gain comes from the cache of an earlier block
    actions = [[env.action_space.sample() for _ in range(args.episodes)] for _ in range(args.repeat)]

    def steps(r: int) -> None:
        for a in actions[r]:
            env.reset()
            env.step(a)

    def seeded_steps(r: int) -> None:
        for i, a in enumerate(actions[r]):
            env.reset(seed=r * args.episodes + i)
            env.step(a)

    scattered = np.random.default_rng(args.seed).permutation(10 * args.repeat * args.episodes)[::10].reshape(args.repeat, -1)

    def scattered_steps(r: int) -> None:
        for s, a in zip(scattered[r].tolist(), actions[r], strict=True):
            env.reset(seed=s)
            env.step(a)

    (step_rate, step_median), (seeded_rate, seeded_median), (scattered_rate, scattered_median) = alternating_rates(
        args.episodes, [steps, seeded_steps, scattered_steps], args.repeat)
    print(f"{args.backend}, {args.track_length}-frame box tracks, sim source; best (median) of {args.repeat} timed blocks")
    print(f"[1] gym.make + reset + step: {step_rate:,.0f} ({step_median:,.0f}) steps/s (target >= 1,000)")
    print(f"[1b] reset(seed=i) + step (a Gymnasium evaluation loop): {seeded_rate:,.0f} ({seeded_median:,.0f}) steps/s, "
          f"{step_rate / seeded_rate:.2f}x the time of reset() + step (target <= 1.5x)")
    print(f"[1c] reset(seed=s) + step, scattered seeds (each prepared alone): {scattered_rate:,.0f} ({scattered_median:,.0f}) "
          f"steps/s, {step_rate / scattered_rate:.2f}x the time of reset() + step")

    u = cast("FilterTuneEnv", env.unwrapped)  # gymnasium types env.unwrapped as a plain Env
    rng = np.random.default_rng(args.seed)
    batches = rng.uniform(-1, 1, (args.repeat, args.calls, args.candidates, u.action_map.dim)).astype(np.float32)

    def scores(r: int) -> None:
        for b in batches[r]:
            env.reset()
            u.score(b)

    score_rate, score_median = rates(args.calls * args.candidates, scores, args.repeat)
    print(f"[2] batched score(), {args.candidates} candidates per call: {score_rate:,.0f} ({score_median:,.0f}) "
          "episodes/s (target >= 5,000)")

    env.reset(seed=args.seed)
    ep = cast("Episode", u.episode)  # set by the reset
    params = u.action_map.to_params(actions[0][0], ep.nominal)
    filter_rate, _ = rates(args.episodes,
                           lambda r: [run_positions(args.backend, ep.y, ep.tau, params) for _ in range(args.episodes)],
                           args.repeat)
    print(f"[3] the filter alone (one candidate, its gains cached): {filter_rate:,.0f} runs/s; a step costs "
          f"{filter_rate / step_rate:.1f} filter runs (a step includes a rule run, the simulation, features, scoring)")

    vec_rate, vec_median, filterpy_rate, faults = batched_rates(args)
    target = {"ufir_cmn": 10_000, "kf_cmn": 6_000}.get(args.backend)
    print(f"[4] batched vec env, {args.n_envs} envs: {vec_rate:,.0f} ({vec_median:,.0f}) env steps/s"
          + (f" (target >= {target:,})" if target else "") + f"; {vec_rate / step_rate:.1f}x [1]; filterpy KalmanFilter "
          f"loop on the same tracks: {filterpy_rate:,.1f} tracks/s (batched env steps/s: {vec_rate / filterpy_rate:,.0f}x that); "
          f"{kernel_threads()} kernel threads, {faults:,.0f} minor page faults a step")
    return 0


def minor_faults() -> int:
    """The process's minor page faults so far."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def batched_rates(args) -> tuple[float, float, float, float]:
    """[4]: (best, median) env steps/s of the batched vec env, filterpy's tracks/s on its tracks and the minor page
    faults a vec env step (pages the step's arrays mapped afresh: ``bboxtune.filters.allocator``)."""
    venv = make_vec("bboxtune/FilterTune-v0", {"backend": args.backend, "track_length": args.track_length},
                    split="train", n_envs=args.n_envs, seed=args.seed, vec_env="batched")
    venv.reset()
    rng = np.random.default_rng(args.seed)
    n_actions = cast("tuple[int, ...]", venv.action_space.shape)[0]  # a Box
    actions = rng.uniform(-1, 1, (args.repeat, args.vec_steps, args.n_envs, n_actions)).astype(np.float32)

    def vec_steps(r: int) -> None:
        for a in actions[r]:
            venv.step(a)

    before = minor_faults()
    best, median = rates(args.vec_steps * args.n_envs, vec_steps, args.repeat)
    faults = (minor_faults() - before) / (args.repeat * args.vec_steps)
    episodes = [p[0] for p in cast("TuneVecEnv", venv).batch.prepared[:args.filterpy_tracks]]  # vec_env="batched"
    y = np.stack([ep.y for ep in episodes])
    model = filters.constant_velocity(float(episodes[0].tau), ndim=4)  # filterpy's cost does not depend on τ
    nominal = episodes[0].nominal
    x0, P0 = np.concatenate([y[0, 0], np.zeros(4)]), np.diag([nominal.sigma_v**2] * 4 + [1e6] * 4)
    filterpy_rate, _ = rates(len(episodes), lambda r: filterpy_loop(y, model, nominal.sigma_w, nominal.sigma_v, x0, P0), 1)
    return best, median, filterpy_rate, faults
