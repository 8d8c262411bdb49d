#!/usr/bin/env python
"""Compare a trained tuner with every baseline on the same held-out episodes of its env and back end.

    python scripts/compare.py --model runs/ppo_ufir_cmn_sim_s0 --episodes 500

Methods (agents.baselines, agents.adaptive): rule, rule_est_sigma, rule_true_sigma (sim only), oracle,
global, amortised, adaptive, the trained model (named by its algorithm, e.g. ppo) and its best-on-validation
checkpoint (<algo>_best). Test episodes are the test split (noise seeds 10⁹ + i, agents/splits.py) for every
method (common random numbers); global and amortised are fitted on train-split episodes.

Writes to --out (default RUN_DIR/compare): results.csv (one row per method × episode), summary.md (tables
with 95 % bootstrap CIs), gain_boxplot.png, otb_curves.png, trajectory.png.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

import torch  # noqa: E402

from agents.baselines import GridSearch  # noqa: E402
from agents.evaluate import BaselineSettings, evaluate, fit_baselines, standard_policies  # noqa: E402
from agents.plots import gain_boxplot, otb_curves, trajectories  # noqa: E402
from agents.report import by_method, summary_markdown, write_results_csv  # noqa: E402
from agents.runs import HelpFormatter, SB3Policy, load_config, make_env  # noqa: E402
from agents.splits import eval_seeds  # noqa: E402

ONE_STEP_ENV = "bboxtune/FilterTune-v0"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("--model", type=Path, required=True, metavar="RUN_DIR", help="a scripts/train.py run directory")
    p.add_argument("--episodes", type=int, default=500, help="test episodes (test split episodes 0 .. N-1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the baselines' training episodes, Optuna, the regressor and the bootstrap")
    p.add_argument("--out", type=Path, default=None, help="output folder (default RUN_DIR/compare)")
    p.add_argument("--train-episodes", type=int, default=1000, help="train episodes for the amortised regressor")
    p.add_argument("--global-trials", type=int, default=64, help="Optuna TPE trials of the global tuner")
    p.add_argument("--oracle-budget", type=int, default=300, help="first-stage candidates of the oracle's grid search")
    p.add_argument("--bootstrap", type=int, default=2000, help="bootstrap resamples")
    args = p.parse_args(argv)
    for name in ("episodes", "train_episodes", "global_trials", "oracle_budget", "bootstrap"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')}={getattr(args, name)}: allowed integers >= 1")
    return args


def main(argv: list[str] | None = None) -> Path:
    args = parse_args(argv)
    torch.set_num_threads(1)
    command = shlex.join(["python", "scripts/compare.py", *(sys.argv[1:] if argv is None else argv)])
    cfg = load_config(args.model)
    out = args.out or args.model / "compare"
    out.mkdir(parents=True, exist_ok=True)
    env_id, env_kwargs, algo = cfg["env_id"], cfg["env_kwargs"], cfg["algo"]
    if env_id != ONE_STEP_ENV:
        raise SystemExit(f"{args.model} was trained on {env_id}; compare.py scores one-step tuners of {ONE_STEP_ENV}")
    print(f"seed: {args.seed}\n{algo} from {args.model}: {env_id} {env_kwargs}, {args.episodes} test episodes")
    search = GridSearch(budget=args.oracle_budget)
    settings = BaselineSettings(train_episodes=args.train_episodes, global_episodes=min(300, args.train_episodes),
                                global_trials=args.global_trials, seed=args.seed)
    standard = standard_policies(env_kwargs["source"], search)
    start = time.perf_counter()
    fitted = fit_baselines(make_env(env_id, env_kwargs, split="train"), standard[-1], settings, progress=True)
    print(f"fitted global and amortised on {args.train_episodes} train episodes in {time.perf_counter() - start:.0f} s")
    learned = [SB3Policy.load(args.model, "final")]
    if (args.model / "best_model.zip").exists():
        best = SB3Policy.load(args.model, "best")
        best.name = f"{algo}_best"
        learned.append(best)
    policies = [*standard, *fitted, *learned]
    start = time.perf_counter()
    result = evaluate(make_env(env_id, env_kwargs, split="test"), policies, eval_seeds("test", args.episodes), progress=True)
    print(f"scored {len(policies) + 1} methods on {args.episodes} episodes in {time.perf_counter() - start:.0f} s")
    write_results_csv(out / "results.csv", result.rows)
    title = f"{algo} vs baselines · {env_id} · backend {env_kwargs['backend']} · source {env_kwargs['source']}"
    gain_boxplot(out / "gain_boxplot.png", by_method(result.rows, "log_ratio"), title)
    otb_curves(out / "otb_curves.png", result.success, result.precision, title)
    ex = result.example
    trajectories(out / "trajectory.png", ex["truth"], ex["y"], {k: v for k, v in ex["estimates"].items()
                 if k in ("rule", "oracle", "amortised", algo)}, f"{title}\ntest episode 0: " + ", ".join(
                     f"{k} {v:.3g}" for k, v in ex["meta"].items() if isinstance(v, float)))
    settings_md = {"command": f"`{command}`", "model": f"`{args.model}` ({cfg['total_timesteps']} timesteps, seed {cfg['seed']})",
                   "test episodes": f"{args.episodes} (test split: noise seeds 10⁹ + i, i < {args.episodes})",
                   "baselines fitted on": f"{args.train_episodes} train-split episodes (seed {args.seed}); global: "
                                          f"{args.global_trials} TPE trials on {settings.global_episodes} of them",
                   "oracle": f"grid of <= {search.budget} actions, then {search.rounds} local refinements "
                             f"({search.refine} points per dimension); the rules' actions are candidates"}
    summary = summary_markdown(result.rows, result.truth_at_test, learned=[p.name for p in learned], title=title,
                               settings=settings_md, figures=["gain_boxplot.png", "otb_curves.png", "trajectory.png"],
                               n_boot=args.bootstrap, seed=args.seed)
    (out / "summary.md").write_text(summary)
    print(summary.split("## Paired")[0])
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    main()
