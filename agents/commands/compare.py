"""Compare a trained tuner with every baseline on the same held-out episodes of an env and back end.

    python scripts/compare.py --model runs/ppo_ufir_cmn_sim_s0 --episodes 500
    python scripts/compare.py --model runs/ppo_ufir_cmn_sim_s0 --env-kwargs source=otb          # transfer: OTB replay
    python scripts/compare.py --model RUN --env-kwargs source=otb_tracker "trackers=[SiamRPN++, CFNet, STRUCK, MDNet]"
    python scripts/compare.py --model runs/ppo_s0 runs/ppo_s1 runs/ppo_s2 --out runs/ppo_seeds   # across training seeds

The env: the run's own (config.yml's env id and env_kwargs) unless --env / --env-kwargs KEY=VALUE ... change it (any
bboxtune.envs.episodes.config.EnvConfig field, YAML values, KEY:VALUE also accepted, split at the first = or :;
checked before any work). The model must fit the evaluation env: equal observation and action spaces and actions that
set the same parameters of the same back end (bboxtune.agents.training.safe_load.check_env_match); everything else may
differ (transfer).

Episodes (agents/splits.py): --split (default test) and --seed choose them, the same seed always the same
episodes. sim / video: --episodes N noise seeds of the split (seed 0: episodes 0 .. N-1, today's fixed test set;
another seed: N others drawn with it). OTB sources enumerate instead (no --episodes): "otb" every sequence of the
split × --seeds-per-sequence noise seeds, "otb_tracker" every sequence × every tracker of the env's set (tracker
output has no noise seed). --seed also seeds the baselines' training episodes, Optuna, the regressor and the
bootstrap.

Methods (bboxtune.agents.policies.baselines, bboxtune.agents.policies.adaptive): raw (the measurements themselves, no
filter; a frame without a measurement is scored as a missing estimate: a failure for success AUC / precision, left out
of the RMSE), bytetrack_kf and sort_kf (the box filters ByteTrack / DeepSORT and SORT ship, published settings), rule
(bytetrack_kf: stock ByteTrack), rule_est_sigma, rule_true_sigma (sim only; neither for bytetrack_kf), oracle
(per-episode search maximising the env's reward with the truth), oracle_auc (maximising success AUC; oracle_rmse,
minimising RMSE, when the reward is not RMSE), global, amortised, adaptive, the trained model (named by its algorithm,
e.g. ppo) and its best-on-validation checkpoint (<algo>_best); with --gate also each final model gated (<algo>_gated,
bboxtune.agents.evaluation.gate: its action where a ridge regressor predicts that it beats the raw measurements by
more than a margin chosen on val episodes; elsewhere the measurements left alone, scored as raw; each fitted gate is
written to gates/<name>.json, for smooth.py --gate). All methods see the same episodes (common random numbers); global
and amortised are fitted on train-split episodes of the evaluation env, the gates on train- and val-split episodes of
the run's own env (so a transfer evaluation stays one).

Runs of bboxtune/FilterRetune-v0 (re-tuning every window) are scored by bboxtune.agents.evaluation.retune_eval
instead: raw, rule (every
window), oneshot_oracle (the best single action for the track, with the truth), oneshot_learned (--oneshot-model
RUN_DIR: a FilterTune-v0 run's action for the whole track, chosen seeing the whole track; left out without it) and
oneshot_learned_online (the same model choosing from the warm-up window only), window_oracle (greedy per-window
search with the truth, carrying the filter state), window_amortised (a learned sequential tuner without RL: a
regressor from the window's observation to every candidate action's log RMSE on the coming window, fitted on
--train-episodes train episodes, bboxtune.agents.evaluation.window_regressor; --fit-seeds K fits K of them), window_anchored (with
--oneshot-model: the same regressor anchored at oneshot_learned's action, leaving it in a window only for a
predicted gain above a margin chosen on --val-episodes val episodes or set with --anchor-margin), window_residual (with
--oneshot-model: a second regressor whose candidates are oneshot_learned's action moved by small offsets, leaving it the
same way), adaptive (Sage–Husa), imm
(IMM over two KF tunings) and the trained model(s), all on the frames after the warm-up window; summary.md adds
the share of the one-shot → per-window gap each method closes, the paired log-ratio of every sequential tuner
against oneshot_learned and, with several --model or --fit-seeds K > 1, their IQM and mean across seeds;
parameter_schedule.png shows test episode 0's parameters per window against its true
regime switches (scenario=nonstationary).

    python scripts/compare.py --model runs/ppo_retune --oneshot-model runs/ppo_oneshot --env-kwargs scenario=nonstationary
    python scripts/compare.py --env bboxtune/FilterRetune-v0 --env-kwargs scenario=nonstationary window=10 \
        --oneshot-model runs/ppo_oneshot --out runs/retune_baselines                  # no trained re-tuner

Without --model (only with --env bboxtune/FilterRetune-v0, and --out) the same comparison runs without a trained
sequential tuner, in the env that --env-kwargs sets on EnvConfig's defaults: the baselines, oracles and window
regressors only, which need no RL run. --regime-informed (scenario=nonstationary, source sim) adds
window_regime_informed[_s<k>] (window_amortised fitted and asked with the true regime schedule around each window
after its observation) and regime_oracle (in each window of a true regime state the action best over that
state's windows, with the truth) (bboxtune.agents.evaluation.regime_informed): references that use the truth, for how much of the
one-shot → per-window gap knowing the regimes reaches.

Writes to --out (default RUN_DIR/compare; a new or empty folder, nothing is overwritten): results.csv (one row per
method × episode: method, episode, sequence, tracker, rmse, success_auc, precision20, …; sequence and tracker empty
for sim), summary.md (tables with 95 % bootstrap CIs that resample sequences — an OTB sequence or a synthetic video
with all its episodes — and simulated episodes, each its own cluster; sources other than sim add success AUC /
precision against raw and rule, OTB sources per-attribute deltas and, for otb_tracker, rows per tracker),
gain_boxplot.png, otb_curves.png, trajectory.png; with several --model (runs of one algorithm and env, distinct seeds)
every model is scored on the same episodes as <algo>_s<seed> / <algo>_best_s<seed> beside one set of baselines, and
summary.md adds their IQM and mean across seeds with stratified bootstrap CIs (rliable's estimator,
bboxtune.agents.evaluation.seeds_report) and, for FilterTune-v0 runs, performance_profile.png. The run's models are
loaded without unpickling anything and checked against its config.yml (bboxtune.agents.training.safe_load) and against
the evaluation env before any baseline is fitted; an input that never varied in a model's training is held at its
training value (bboxtune.agents.training.runs.hold_constant_features) and summary.md names those inputs; an old run
whose statistics are only in vecnormalize.pkl is refused unless --trust-pickle is given (pickles can run code: only
for runs you trust). Bad arguments or run files: one line naming them, exit status 2.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import torch

from bboxtune.agents.cli import (
    ArgumentParser,
    HelpFormatter,
    command,
    existing_dir,
    int_range,
    key_values,
    nonnegative_int,
    out_dir,
    positive_int,
    tracker_set,
)
from bboxtune.agents.commands.compare_retune import (
    ONE_STEP_ENV,
    RETUNE_ENV,
    add_retune_arguments,
    check_regime_source,
    check_retune_flags,
    compare_retune,
    load_oneshot,
    no_run_config,
)
from bboxtune.agents.episodes import check_bank_memory
from bboxtune.agents.evaluation.evaluate import (
    MAX_BASELINES,
    OTB_SOURCES,
    BaselineSettings,
    check_evaluation_memory,
    evaluate,
    evaluation_episodes,
    fit_baselines,
    standard_policies,
)
from bboxtune.agents.evaluation.gate import GATED, fit_gates
from bboxtune.agents.evaluation.plots import gain_boxplot, otb_curves, performance_profile, trajectories
from bboxtune.agents.evaluation.report import by_method, summary_markdown, write_results_csv
from bboxtune.agents.evaluation.seeds_report import profile_curves, seeds_section
from bboxtune.agents.evaluation.window_regressor import WINDOW_AMORTISED, WINDOW_ANCHORED, WINDOW_RESIDUAL
from bboxtune.agents.policies.baselines import GridSearch, OraclePolicy
from bboxtune.agents.policies.gate_file import write_gate
from bboxtune.agents.splits import SPLIT_SIZE, SPLITS, EpisodeSpec
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import ENV_ERRORS, SB3Policy, check_free, describe_held_features, load_config, make_env
from bboxtune.agents.training.seed_runs import describe_models, load_learned, load_seed_runs
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.data.memory import MemoryLimitError
from bboxtune.envs.episodes.config import EnvConfig

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.agents.evaluation.gate import GatedPolicy
    from bboxtune.envs.episodes.sources import OTBSource
    from bboxtune.envs.track_env import TrackEnv

ENVS = (ONE_STEP_ENV, RETUNE_ENV)
MIN_TRAIN_EPISODES = 11  # AmortisedPolicy's MLP holds out ceil(10 %) for early stopping and needs >= 2 of them
DEFAULT_EPISODES = 500  # sim / video
DEFAULT_SEEDS_PER_SEQUENCE = 5  # source otb: 23 test sequences × 5 = 115 episodes
GATES = "gates"  # --gate: the fitted gates, <name>.json (bboxtune.agents.policies.gate_file), for smooth.py --gate
# sim / video val episodes the margins of window_anchored/_residual (--oneshot-model) and the gates (--gate) are chosen on
DEFAULT_VAL_EPISODES = 100


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="compare.py", description=__doc__, formatter_class=HelpFormatter, allow_abbrev=False)
    p.add_argument("--model", type=existing_dir, nargs="+", default=None, metavar="RUN_DIR",
                   help="a scripts/train.py run directory; several (runs of one env and algorithm, e.g. training seeds): "
                        "each scored on the same episodes as <algo>_s<seed>, and summary.md adds IQM and mean across "
                        "them with stratified bootstrap CIs (bboxtune.agents.evaluation.seeds_report; FilterTune-v0 runs also "
                        f"performance_profile.png); needs --out. Required, except with --env {RETUNE_ENV} (then the "
                        "re-tuning baselines and window regressors only, in the env of --env-kwargs)")
    p.add_argument("--env", default=None, metavar="ID",
                   help=f"env id (default: the run's; one of {ENVS}, the run's kind); without --model: {RETUNE_ENV}")
    p.add_argument("--env-kwargs", nargs="*", default=[], metavar="KEY=VALUE",
                   help="override the run's env arguments (bboxtune.envs.episodes.config.EnvConfig fields, YAML values; "
                        "KEY:VALUE also accepted), e.g. source=otb track_length=100; the split is --split")
    p.add_argument("--trackers", type=tracker_set, default=None, metavar="SET",
                   help="source otb_tracker: score these trackers' output instead of the run's: 'test' (the held-out "
                        "trackers of bboxtune.envs.data.otb.TRACKER_SPLIT), 'train' or comma-separated names")
    p.add_argument("--split", default="test", choices=SPLITS, help="which split's episodes (and OTB sequences) are scored")
    p.add_argument("--episodes", type=int_range(1, SPLIT_SIZE), default=None,
                   help=f"sim / video: episodes scored (default {DEFAULT_EPISODES}); OTB sources enumerate theirs "
                        "and take no count")
    p.add_argument("--seeds-per-sequence", type=positive_int, default=None, metavar="K",
                   help=f"source otb: noise seeds per sequence (default {DEFAULT_SEEDS_PER_SEQUENCE})")
    p.add_argument("--seed", type=nonnegative_int, default=0,
                   help="which episodes are scored (0: episodes 0 .. N-1 of the split), and the seed of the baselines' "
                        "training episodes, Optuna, the regressor and the bootstrap")
    p.add_argument("--out", type=out_dir, default=None, help="output folder, new or empty (default RUN_DIR/compare)")
    p.add_argument("--train-episodes", type=int_range(MIN_TRAIN_EPISODES), default=1000,
                   help=f"train episodes for the amortised regressor ({RETUNE_ENV} runs: for {WINDOW_AMORTISED}, each "
                        "of its windows a sample) (>= 11: it holds out 10 %% for early stopping, which needs 2)")
    p.add_argument("--global-trials", type=positive_int, default=64, help="Optuna TPE trials of the global tuner")
    p.add_argument("--oracle-budget", type=positive_int, default=300, help="first-stage candidates of the oracle's grid search")
    p.add_argument("--bootstrap", type=positive_int, default=2000, help="bootstrap resamples")
    add_retune_arguments(p)
    p.add_argument("--val-episodes", type=int_range(1, SPLIT_SIZE), default=None,
                   help=f"{RETUNE_ENV} runs with --oneshot-model: val-split episodes the margins of {WINDOW_ANCHORED} and "
                        f"{WINDOW_RESIDUAL} are chosen on; with --gate, those of the gates (default {DEFAULT_VAL_EPISODES}; "
                        "sim and video sources: OTB sources take every val sequence, once for the anchored margins and "
                        "--seeds-per-sequence times for the gates, and every tracker's output of it)")
    p.add_argument("--gate", action="store_true",
                   help=f"{ONE_STEP_ENV} runs: also score each final model gated as <algo>{GATED}[_s<seed>] "
                        "(bboxtune.agents.evaluation.gate: "
                        "its action where a regressor predicts it beats the raw measurements by more than a margin, else "
                        "the measurements left alone; fitted on --train-episodes train and chosen on --val-episodes val "
                        "episodes of the run's own env)")
    p.add_argument("--trust-pickle", action="store_true",
                   help="accept an old run's pickled vecnormalize.pkl (pickles can run code: only for runs you trust)")
    return p


def evaluation_env(parser: ArgumentParser, args: argparse.Namespace, cfg: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The env id and kwargs to evaluate in: the run's (without --model: :func:`no_run_config`'s), changed by --env /
    --env-kwargs (checked here)."""
    env_id = args.env or cfg["env_id"]
    if env_id != cfg["env_id"]:
        parser.error(f"--env {env_id}: {args.model} was trained on {cfg['env_id']}; compare.py scores a run on its own env id")
    check_retune_flags(parser.error, args, env_id)
    if args.gate and env_id != ONE_STEP_ENV:
        parser.error(f"--gate: only for runs of {ONE_STEP_ENV} (this one is of {env_id})")
    if args.val_episodes is not None and args.oneshot_model is None and not args.gate:
        parser.error(f"--val-episodes: only with --oneshot-model ({WINDOW_ANCHORED} and {WINDOW_RESIDUAL}'s margins) or "
                     "--gate (the gates' margins)")
    if args.val_episodes is not None and args.anchor_margin is not None:
        parser.error("--val-episodes: not used with --anchor-margin (no margin is chosen)")
    args.val_episodes = args.val_episodes or DEFAULT_VAL_EPISODES
    try:
        overrides = key_values("--env-kwargs", args.env_kwargs)
    except ValueError as err:
        parser.error(str(err))
    if "split" in overrides:
        parser.error("--env-kwargs split: the split is chosen with --split")
    if args.trackers is not None:
        if "trackers" in overrides:
            parser.error("--trackers: given twice (also in --env-kwargs trackers=...)")
        overrides["trackers"] = list(args.trackers)
    env_kwargs = {**cfg["env_kwargs"], **overrides}
    try:
        config = EnvConfig.from_kwargs(**{**env_kwargs, "split": args.split})
    except (TypeError, ValueError) as err:
        parser.error(f"{env_flags(args)}: {err}" if overrides else f"{args.model}/config.yml: env_kwargs: {err}")
    check_regime_source(parser.error, args, config)
    return env_id, env_kwargs


def env_flags(args: argparse.Namespace) -> str:
    """The flags that changed the run's env, for error messages ("" if none)."""
    return "/".join(flag for flag, given in (("--env-kwargs", args.env_kwargs), ("--trackers", args.trackers)) if given)


def episode_plan(parser: ArgumentParser, args: argparse.Namespace, env: gym.Env, n_runs: int) -> list[EpisodeSpec]:
    """The episodes to score (bboxtune.agents.evaluation.evaluate.evaluation_episodes), after checking the flags that
    choose them, and that scoring them (the baselines and up to 3 methods per run of ``n_runs``) and the
    ``--train-episodes`` bank the baselines are fitted on fit in memory."""
    source = cast("TrackEnv", env.unwrapped).config.source
    k = args.seeds_per_sequence
    if source in OTB_SOURCES and args.episodes is not None:
        parser.error(f"--episodes: source {source!r} enumerates its episodes (every {args.split}-split sequence × "
                     f"{'tracker' if source == 'otb_tracker' else '--seeds-per-sequence noise seeds'}); leave it out")
    if source != "otb" and k is not None:
        parser.error(f"--seeds-per-sequence applies to source 'otb' only (this evaluation's source is {source!r}: "
                     f"{'one episode per sequence × tracker' if source == 'otb_tracker' else 'use --episodes'})")
    n = (args.episodes or DEFAULT_EPISODES) if source not in OTB_SOURCES else None
    k = (k or DEFAULT_SEEDS_PER_SEQUENCE) if source == "otb" else None
    chosen = (n, f"--episodes {n}") if n is not None else None  # otb_tracker: one per sequence × tracker, not chosen
    if k is not None:
        chosen = (len(cast("OTBSource", cast("TrackEnv", env.unwrapped).source).sequences) * k, f"--seeds-per-sequence {k}")
    try:
        if chosen is not None:
            count, flag = chosen
            check_evaluation_memory(count, MAX_BASELINES + 3 * n_runs, args.bootstrap, flag)
        check_bank_memory(args.train_episodes, cast("TrackEnv", env.unwrapped).source.max_frames(),
                          f"--train-episodes {args.train_episodes}")
    except MemoryLimitError as err:
        parser.error(str(err))
    return evaluation_episodes(env, args.split, episodes=n, seeds_per_sequence=k, seed=args.seed)


def describe_episodes(args: argparse.Namespace, source: str, episodes: list[EpisodeSpec]) -> str:
    """The settings line of the scored episodes."""
    n = len(episodes)
    if source in OTB_SOURCES:
        sequences = len({e.sequence for e in episodes})
        per = (f"× {len({e.tracker for e in episodes})} trackers (one episode per sequence with the tracker's output)"
               if source == "otb_tracker" else f"× {n // sequences} noise seeds")
        return f"{n} = {sequences} {args.split}-split sequences {per}; noise seeds chosen with --seed {args.seed}"
    if args.split == "test" and args.seed == 0:
        return f"{n} (test split: noise seeds 10⁹ + i, i < {n})"
    return f"{n} ({args.split} split, chosen with --seed {args.seed}: bboxtune.agents.splits.split_seeds)"


def run(argv: list[str] | None = None) -> Path:
    """Score the run(s) the command line ``argv`` names; returns the output folder."""
    parser = build_parser()
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    command = shlex.join(["python", "scripts/compare.py", *(sys.argv[1:] if argv is None else argv)])
    runs, args.model = args.model or [], (args.model or [None])[0]
    if not runs and args.env != RETUNE_ENV:
        parser.error(f"--model: required (a {ONE_STEP_ENV} comparison scores a trained run); without one, --env "
                     f"{RETUNE_ENV} scores the re-tuning baselines and window regressors only")
    if len(runs) != 1 and args.out is None:
        parser.error("--out: required with several --model" if runs else "--out: required without --model")
    out = args.out or args.model / "compare"
    groups: dict[str, list[str]] = {}
    learned: list[SB3Policy] = []
    try:  # everything that can be checked is checked before the (long) fitting and scoring
        check_free(out, "choose another --out")
        cfg = load_config(args.model) if runs else no_run_config()
        if cfg["env_id"] not in ENVS:
            raise RunError(f"{args.model} was trained on {cfg['env_id']}; compare.py scores runs of {ENVS}")
        env_id, env_kwargs = evaluation_env(parser, args, cfg)
        try:
            test_env, train_env = make_env(env_id, env_kwargs, split=args.split), make_env(env_id, env_kwargs, split="train")
        except ENV_ERRORS as err:
            raise RunError(f"{env_flags(args) or '--model'}: env {env_id} {env_kwargs} cannot be built "
                           f"({' '.join(str(err).split())})") from None
        episodes = episode_plan(parser, args, test_env, len(runs))
        if len(runs) > 1:
            learned, groups = load_seed_runs(runs, cfg, test_env, args.trust_pickle)
        elif runs:
            learned = load_learned(args.model, cfg, test_env, args.trust_pickle)
        oneshot = load_oneshot(args, env_kwargs) if args.oneshot_model is not None else None
        out.mkdir(parents=True, exist_ok=True)
    except (RunError, OSError) as err:
        parser.error(str(err))
    models = (learned, groups, describe_models(args.model, runs, learned, cfg))
    if env_id == RETUNE_ENV:
        described = describe_episodes(args, cast("TrackEnv", test_env.unwrapped).config.source, episodes)
        return compare_retune(args, cfg, (test_env, train_env, env_kwargs), (episodes, described), models, oneshot, out,
                              command)
    config = cast("TrackEnv", test_env.unwrapped).config
    algo, source = cfg["algo"], config.source
    print(f"seed: {args.seed}\n{algo} from {args.model}: {env_id} {env_kwargs}, {len(episodes)} {args.split} episodes")
    search = GridSearch(budget=args.oracle_budget)
    settings = BaselineSettings(train_episodes=args.train_episodes, global_episodes=min(300, args.train_episodes),
                                global_trials=args.global_trials, seed=args.seed)
    standard = standard_policies(source, search, config.reward, backend=config.backend)
    oracle = next(p for p in standard if isinstance(p, OraclePolicy) and p.name == "oracle")
    start = time.perf_counter()
    fitted = fit_baselines(train_env, oracle, settings, progress=True)
    print(f"fitted global and amortised on {args.train_episodes} train episodes in {time.perf_counter() - start:.0f} s")
    gated: list[GatedPolicy] = []
    gate_line, fitted_on = None, ""
    if args.gate:
        start = time.perf_counter()
        finals = [p for p in learned if not p.name.startswith(f"{algo}_best")]
        gated, fitted_on, choices = fit_gates(finals, env_id, cfg["env_kwargs"], train_episodes=args.train_episodes,
                                              n_val=args.val_episodes, seeds_per_sequence=args.seeds_per_sequence or
                                              DEFAULT_SEEDS_PER_SEQUENCE, seed=args.seed)
        gate_line = f"{fitted_on}; " + "; ".join(choices)
        print(f"fitted {len(gated)} gate(s) in {time.perf_counter() - start:.0f} s: {gate_line}")
        if groups:
            groups[f"{algo}{GATED}"] = [p.name for p in gated]
    policies = [*standard, *fitted, *learned, *gated]
    start = time.perf_counter()
    result = evaluate(test_env, policies, episodes, progress=True)
    print(f"scored {len(policies) + 2} methods on {len(episodes)} episodes in {time.perf_counter() - start:.0f} s")
    write_results_csv(out / "results.csv", result.rows)
    title = f"{algo} vs baselines · {env_id} · backend {config.backend} · source {source}"
    gain_boxplot(out / "gain_boxplot.png", by_method(result.rows, "log_ratio"), title)
    otb_curves(out / "otb_curves.png", result.success, result.precision, title)
    ex = result.example
    trajectories(out / "trajectory.png", ex["truth"], ex["y"], {k: v for k, v in ex["estimates"].items()
                 if k in ("rule", "oracle", "amortised", learned[0].name)}, f"{title}\ntest episode 0: " + ", ".join(
                     f"{k} {v:.3g}" for k, v in ex["meta"].items() if isinstance(v, float)))
    changed = sorted(k for k, v in env_kwargs.items() if k not in cfg["env_kwargs"] or cfg["env_kwargs"][k] != v)
    other = "oracle_auc: the same search maximising success AUC" if config.reward == "rmse" else \
        "oracle_rmse: the same search minimising RMSE"
    settings_md = {"command": f"`{command}`", "model": models[2],
                   "inputs held at their training value": describe_held_features({p.name: p.normalizer for p in learned}),
                   "env": f"`{env_kwargs}`" + (f" (changed from the run's: {changed})" if changed else
                                                " (the run's own)"),
                   "test episodes": describe_episodes(args, source, episodes),
                   "baselines fitted on": f"{args.train_episodes} train-split episodes of this env (seed {args.seed}); global: "
                                          f"{args.global_trials} TPE trials on {settings.global_episodes} of them",
                   "oracle": f"grid of <= {search.budget} actions, then {search.rounds} local refinements "
                             f"({search.refine} points per dimension) maximising the env's reward ({config.reward}); "
                             f"{other}; the rules' actions are candidates",
                   **({"gate (--gate)": gate_line} if gate_line else {})}
    pool = cast("OTBSource", cast("TrackEnv", test_env.unwrapped).source)  # used where source is an OTB one
    attributes = ({name: pool.dataset.sequence(name).attributes for name in
                   {cast(str, e.sequence) for e in episodes}} if source in OTB_SOURCES else None)  # OTB: all named
    summary = summary_markdown(result.rows, result.truth_at_test, learned=[p.name for p in (*learned, *gated)],
                               title=title,
                               settings=settings_md, figures=["gain_boxplot.png", "otb_curves.png", "trajectory.png",
                                                                 *(["performance_profile.png"] if groups else [])],
                               n_boot=args.bootstrap, seed=args.seed,
                               rmse_oracle="oracle" if config.reward == "rmse" else "oracle_rmse", attributes=attributes)
    if groups:
        scored = {r["method"] for r in result.rows}
        references = {m: [m] for m in ("raw", "rule_est_sigma", "amortised", "oracle") if m in scored}
        taus, curves = profile_curves(result.rows, {**groups, **references}, n_boot=args.bootstrap, seed=args.seed)
        performance_profile(out / "performance_profile.png", taus, curves, title)
        head, figures = summary.split("## Figures")
        summary = head + seeds_section(result.rows, groups, n_boot=args.bootstrap, seed=args.seed,
                                       reference=("raw", "rule", "oracle")) + "\n## Figures" + figures
    if gated:
        (out / GATES).mkdir(exist_ok=True)
        for policy in gated:
            write_gate(out / GATES / f"{policy.name}.json", policy.gate, about=f"{policy.name}: {fitted_on}")
    write_text_atomic(out / "summary.md", summary)
    print(summary.split("## Paired")[0])
    print(f"wrote {out}")
    return out


@command
def main(argv: list[str] | None = None) -> int:
    """The command line: :func:`run`; exit status 0 (a bad argument exits 2 with one line)."""
    run(argv)
    return 0
