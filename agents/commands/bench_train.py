"""Training benchmark: the default ``python scripts/train.py`` run against SB3's PPO on CartPole-v1, same run.

    python scripts/bench_train.py [--timesteps 100000] [--out DIR] [-- TRAIN_ARGS ...]

Runs, each in a fresh subprocess (so each one's wall time includes its imports and its peak RSS is its own):

1. ``scripts/train.py --timesteps N --out DIR [TRAIN_ARGS]`` — the default run (ufir_cmn, sim, PPO, the batched
   vec env): wall seconds, peak RSS (target <= 1 GB) and its final validation log-ratio;
2. the peer: stable-baselines3's PPO with its default settings on ``CartPole-v1`` for the same N env steps
   (``PPO("MlpPolicy", "CartPole-v1").learn(N)``): wall seconds;

and prints the ratio train.py / CartPole (target <= 0.75x) and train.py's wall time (target <= 2 minutes on 2 cores for
the default 100,000 steps). The learning target (>= 90 % of the oracle's log-ratio on the compare test set) is
measured by ``python scripts/compare.py --model DIR`` on the run this writes (minutes: the oracle's grid). No unit
test asserts on time.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bboxtune.agents.cli import ArgumentParser, command, out_dir, positive_int

REPO = Path(__file__).resolve().parents[2]  # the checkout: train.py runs as scripts/train.py there
CARTPOLE = ("import sys, torch; from stable_baselines3 import PPO; torch.set_num_threads(1); "
            "PPO('MlpPolicy', 'CartPole-v1', seed=0, device='cpu').learn(int(sys.argv[1]))")


def timed(cmd: list[str]) -> tuple[float, float, str]:
    """Run ``cmd``: (wall seconds, peak RSS of the process in GB, its stdout); exits with its output on failure."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"bench_train.py: {' '.join(cmd)} failed (exit {proc.returncode}):\n{proc.stdout}{proc.stderr}")
    peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss  # the largest child so far: run train.py first
    return wall, max(peak_kb, before) / 1e6, proc.stdout


@command
def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(prog="bench_train.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("--timesteps", type=positive_int, default=100_000, help="env steps of both runs")
    ap.add_argument("--out", type=out_dir, default=None, help="train.py's run directory (default: a temporary one)")
    ap.add_argument("train_args", nargs="*", help="more train.py arguments (after --)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = args.out or Path(tmp) / "run"
        train = [sys.executable, "scripts/train.py", "--timesteps", str(args.timesteps), "--out", str(run_dir),
                 *args.train_args]
        train_s, train_gb, out = timed(train)
        val = next((line for line in out.splitlines() if line.startswith("val mean reward")), "val: not printed")
        cart_s, _, _ = timed([sys.executable, "-c", CARTPOLE, str(args.timesteps)])
    print(f"[1] train.py, {args.timesteps:,} steps: {train_s:.1f} s wall (target <= 120 s on 2 cores for 100,000), "
          f"peak RSS {train_gb:.2f} GB (target <= 1 GB); {val}")
    print(f"[2] SB3 PPO on CartPole-v1, {args.timesteps:,} steps: {cart_s:.1f} s wall")
    print(f"train.py / CartPole: {train_s / cart_s:.3f}x (target <= 0.75x)")
    return 0
