#!/usr/bin/env python
"""Compare a trained tuner with every baseline on the same held-out episodes of its env and back end.

    python scripts/compare.py --model runs/ppo_ufir_cmn_sim_s0 --episodes 500

Methods (agents.baselines, agents.adaptive): rule, rule_est_sigma, rule_true_sigma (sim only), oracle,
global, amortised, adaptive, the trained model (named by its algorithm, e.g. ppo) and its best-on-validation
checkpoint (<algo>_best). Test episodes are the test split (noise seeds 10⁹ + i, agents/splits.py) for every
method (common random numbers); global and amortised are fitted on train-split episodes.

Writes to --out (default RUN_DIR/compare; a new or empty folder, nothing is overwritten): results.csv (one
row per method × episode), summary.md (tables with 95 % bootstrap CIs), gain_boxplot.png, otb_curves.png,
trajectory.png. The run's models are loaded without unpickling anything and checked against its config.yml
(agents.safe_load) before any baseline is fitted; an old run whose statistics are only in vecnormalize.pkl is
refused unless --trust-pickle is given (pickles can run code: only for runs you trust). Bad arguments or run
files: one line naming them, exit status 2.
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
from agents.cli import (ArgumentParser, HelpFormatter, existing_dir, int_range, nonnegative_int, out_dir,  # noqa: E402
                        positive_int)
from agents.run_files import RunError, write_text_atomic  # noqa: E402
from agents.runs import SB3Policy, check_free, load_config, make_env  # noqa: E402
from agents.splits import SPLIT_SIZE, eval_seeds  # noqa: E402

ONE_STEP_ENV = "bboxtune/FilterTune-v0"
MIN_TRAIN_EPISODES = 11  # AmortisedPolicy's MLP holds out ceil(10 %) for early stopping and needs >= 2 of them


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="compare.py", description=__doc__, formatter_class=HelpFormatter, allow_abbrev=False)
    p.add_argument("--model", type=existing_dir, required=True, metavar="RUN_DIR", help="a scripts/train.py run directory")
    p.add_argument("--episodes", type=int_range(1, SPLIT_SIZE), default=500, help="test episodes (test split episodes 0 .. N-1)")
    p.add_argument("--seed", type=nonnegative_int, default=0,
                   help="seed of the baselines' training episodes, Optuna, the regressor and the bootstrap")
    p.add_argument("--out", type=out_dir, default=None, help="output folder, new or empty (default RUN_DIR/compare)")
    p.add_argument("--train-episodes", type=int_range(MIN_TRAIN_EPISODES), default=1000,
                   help="train episodes for the amortised regressor (>= 11: it holds out 10 %% for early stopping, "
                        "which needs 2)")
    p.add_argument("--global-trials", type=positive_int, default=64, help="Optuna TPE trials of the global tuner")
    p.add_argument("--oracle-budget", type=positive_int, default=300, help="first-stage candidates of the oracle's grid search")
    p.add_argument("--bootstrap", type=positive_int, default=2000, help="bootstrap resamples")
    p.add_argument("--trust-pickle", action="store_true",
                   help="accept an old run's pickled vecnormalize.pkl (pickles can run code: only for runs you trust)")
    return p


def load_learned(args: argparse.Namespace, algo: str) -> list[SB3Policy]:
    """The run's final model and, if the run has one, its best-on-validation model (``<algo>_best``)."""
    learned = [SB3Policy.load(args.model, "final", trust_pickle=args.trust_pickle)]
    if (args.model / "best_model.zip").exists():
        best = SB3Policy.load(args.model, "best", trust_pickle=args.trust_pickle)
        best.name = f"{algo}_best"
        learned.append(best)
    return learned


def main(argv: list[str] | None = None) -> Path:
    parser = build_parser()
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    command = shlex.join(["python", "scripts/compare.py", *(sys.argv[1:] if argv is None else argv)])
    out = args.out or args.model / "compare"
    try:  # everything that can be checked is checked before the (long) fitting and scoring
        check_free(out, "choose another --out")
        cfg = load_config(args.model)
        if cfg["env_id"] != ONE_STEP_ENV:
            raise RunError(f"{args.model} was trained on {cfg['env_id']}; compare.py scores one-step tuners of {ONE_STEP_ENV}")
        learned = load_learned(args, cfg["algo"])
        out.mkdir(parents=True, exist_ok=True)
    except (RunError, OSError) as err:
        parser.error(str(err))
    env_id, env_kwargs, algo = cfg["env_id"], cfg["env_kwargs"], cfg["algo"]
    print(f"seed: {args.seed}\n{algo} from {args.model}: {env_id} {env_kwargs}, {args.episodes} test episodes")
    search = GridSearch(budget=args.oracle_budget)
    settings = BaselineSettings(train_episodes=args.train_episodes, global_episodes=min(300, args.train_episodes),
                                global_trials=args.global_trials, seed=args.seed)
    standard = standard_policies(env_kwargs["source"], search)
    start = time.perf_counter()
    fitted = fit_baselines(make_env(env_id, env_kwargs, split="train"), standard[-1], settings, progress=True)
    print(f"fitted global and amortised on {args.train_episodes} train episodes in {time.perf_counter() - start:.0f} s")
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
    settings_md = {"command": f"`{command}`",
                   "model": f"`{args.model}` ({learned[0].model.num_timesteps} timesteps, seed {cfg['seed']})",
                   "test episodes": f"{args.episodes} (test split: noise seeds 10⁹ + i, i < {args.episodes})",
                   "baselines fitted on": f"{args.train_episodes} train-split episodes (seed {args.seed}); global: "
                                          f"{args.global_trials} TPE trials on {settings.global_episodes} of them",
                   "oracle": f"grid of <= {search.budget} actions, then {search.rounds} local refinements "
                             f"({search.refine} points per dimension); the rules' actions are candidates"}
    summary = summary_markdown(result.rows, result.truth_at_test, learned=[p.name for p in learned], title=title,
                               settings=settings_md, figures=["gain_boxplot.png", "otb_curves.png", "trajectory.png"],
                               n_boot=args.bootstrap, seed=args.seed)
    write_text_atomic(out / "summary.md", summary)
    print(summary.split("## Paired")[0])
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    main()
