"""The FilterRetune-v0 part of ``scripts/compare.py``: the re-tuning methods (bboxtune.agents.evaluation.retune_eval),
the per-window regressors it fits (bboxtune.agents.evaluation.window_regressor, ``--fit-seeds``; anchored at the
one-shot model with its margin chosen on val episodes, ``--val-episodes`` / ``--anchor-margin``), the one-shot model
it loads (``--oneshot-model``), and the summary with the one-shot → per-window gap
(bboxtune.agents.evaluation.report_retune), and the flags only these comparisons take (:func:`add_retune_arguments`,
:func:`check_retune_flags`, :func:`check_regime_source`). compare.py parses the arguments."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, cast

import gymnasium as gym
import numpy as np

from bboxtune.agents.cli import existing_dir, float_range, positive_int
from bboxtune.agents.evaluation.evaluate import val_episodes
from bboxtune.agents.evaluation.plots import gain_boxplot, parameter_schedule
from bboxtune.agents.evaluation.regime_informed import (
    REGIME_ORACLE,
    WINDOW_REGIME_INFORMED,
    RegimeInformedPolicy,
    RegimeObservation,
    RegimeOracle,
)
from bboxtune.agents.evaluation.report import by_method, summary_markdown, write_results_csv
from bboxtune.agents.evaluation.report_retune import retune_tables
from bboxtune.agents.evaluation.retune_eval import (
    ONESHOT_LEARNED,
    ONESHOT_ORACLE,
    WINDOW_ORACLE,
    OneShotLearned,
    OneShotOracle,
    Sequential,
    evaluate_retune,
    window_oracle,
)
from bboxtune.agents.evaluation.seeds_report import seeds_section
from bboxtune.agents.evaluation.window_regressor import (
    WINDOW_AMORTISED,
    WINDOW_ANCHORED,
    WINDOW_RESIDUAL,
    AnchoredWindowPolicy,
    WindowRegressorPolicy,
    WindowRegressorSettings,
    fit_regressor,
    select_margin,
)
from bboxtune.agents.policies.baselines import GridSearch, RulePolicy
from bboxtune.agents.splits import EpisodeSpec, train_seeds
from bboxtune.agents.training.run_files import RunError
from bboxtune.agents.training.runs import ENV_ERRORS, SB3Policy, describe_held_features, load_config, make_env
from bboxtune.agents.training.safe_load import check_env_match
from bboxtune.envs import RETUNE_ID, TUNE_ID

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.retune_env import FilterRetuneEnv
    from bboxtune.envs.tune_env import FilterTuneEnv
from bboxtune.envs.data.atomic_files import write_text_atomic
from bboxtune.envs.episodes.config import EnvConfig

ONE_STEP_ENV, RETUNE_ENV = TUNE_ID, RETUNE_ID


def add_retune_arguments(p: argparse.ArgumentParser) -> None:
    """compare.py's flags that only FilterRetune-v0 comparisons take (checked by :func:`check_retune_flags`)."""
    p.add_argument("--fit-seeds", type=positive_int, default=1, metavar="K",
                   help=f"{RETUNE_ENV} runs: fit {WINDOW_AMORTISED} K times (seeds --seed … --seed + K − 1, each on its own "
                        f"--train-episodes train episodes), scored as {WINDOW_AMORTISED}_s<k> when K > 1")
    p.add_argument("--oneshot-model", type=existing_dir, default=None, metavar="RUN_DIR",
                   help=f"{RETUNE_ENV} runs: a {ONE_STEP_ENV} run scored as oneshot_learned (its action for the whole "
                        "track); without it that row is left out")
    p.add_argument("--anchor-margin", type=float_range(0.0), default=None, metavar="M",
                   help=f"{RETUNE_ENV} runs with --oneshot-model: the margin of {WINDOW_ANCHORED} and {WINDOW_RESIDUAL} "
                        "(predicted log-RMSE gain a switch away from the one-shot action must exceed), instead of choosing "
                        "it on val episodes")
    p.add_argument("--regime-informed", action="store_true",
                   help=f"{RETUNE_ENV} with scenario=nonstationary (source sim): also fit {WINDOW_AMORTISED} told the true "
                        f"regime schedule, scored as {WINDOW_REGIME_INFORMED}[_s<k>], and {REGIME_ORACLE}, the best action "
                        "per true regime state chosen with the truth (bboxtune.agents.evaluation.regime_informed: "
                        "references that use the truth, for the share of the one-shot → per-window gap that knowing the "
                        "regimes reaches)")


def check_retune_flags(error: Callable[[str], NoReturn], args: argparse.Namespace, env_id: str) -> None:
    """Refuse (``error``: the parser's, one line, exit 2) the FilterRetune-v0 flags in another env's comparison and
    ``--anchor-margin`` without ``--oneshot-model``."""
    for flag, given in (("--oneshot-model", args.oneshot_model is not None), ("--fit-seeds", args.fit_seeds != 1),
                        ("--regime-informed", args.regime_informed)):
        if given and env_id != RETUNE_ENV:
            error(f"{flag}: only for runs of {RETUNE_ENV} (this one is of {env_id})")
    if args.anchor_margin is not None and args.oneshot_model is None:
        error(f"--anchor-margin: only with --oneshot-model (it sets {WINDOW_ANCHORED} and {WINDOW_RESIDUAL}, which are "
              "anchored there)")


def check_regime_source(error: Callable[[str], NoReturn], args: argparse.Namespace, config: EnvConfig) -> None:
    """Refuse ``--regime-informed`` where episodes have no true regime schedule (anything but non-stationary sim)."""
    if args.regime_informed and (config.source, config.scenario) != ("sim", "nonstationary"):
        error(f"--regime-informed: needs source 'sim' with scenario=nonstationary (a true regime schedule); this "
              f"evaluation's env has source {config.source!r}, scenario {config.scenario!r}")


def no_run_config() -> dict[str, Any]:
    """The stand-in for a run's config.yml without --model: a FilterRetune-v0 env with EnvConfig's defaults (changed
    by --env-kwargs) and no trained tuner."""
    return {"env_id": RETUNE_ENV, "env_kwargs": {}, "algo": None}


def load_oneshot(args: argparse.Namespace, env_kwargs: dict[str, Any]) -> OneShotLearned:
    """``--oneshot-model``: a FilterTune-v0 run's final model, checked against a FilterTune-v0 env with the
    evaluation's arguments (which it observes the whole track in)."""
    cfg = load_config(args.oneshot_model)
    if cfg["env_id"] != ONE_STEP_ENV:
        raise RunError(f"--oneshot-model {args.oneshot_model}: trained on {cfg['env_id']}, not {ONE_STEP_ENV}")
    try:  # the evaluation's arguments with the run's own feature set (what its model observes)
        tune_kwargs = {**env_kwargs, "features": EnvConfig.from_kwargs(**cfg["env_kwargs"]).features}
        tune_env = make_env(ONE_STEP_ENV, tune_kwargs, split=args.split)
    except ENV_ERRORS as err:
        raise RunError(f"--oneshot-model: env {ONE_STEP_ENV} {env_kwargs} cannot be built "
                       f"({' '.join(str(err).split())})") from None
    policy = SB3Policy.load(args.oneshot_model, "final", trust_pickle=args.trust_pickle)
    check_env_match(args.oneshot_model / "model.zip", policy.model, cfg, tune_env)
    return OneShotLearned(policy, tune_env)


@dataclass
class Anchors:
    """``--oneshot-model`` on each split's FilterTune-v0 env (the anchors of ``window_anchored``), and the val
    split's FilterRetune-v0 env and episodes its margin is chosen on."""

    by_split: dict[str, OneShotLearned]
    val_env: gym.Env
    val_episodes: list[EpisodeSpec]

    @classmethod
    def build(cls, oneshot: OneShotLearned, env_kwargs: dict[str, Any], n_val: int) -> Anchors:
        tune_kwargs = {**env_kwargs, "features": cast("FilterTuneEnv", oneshot.tune_env.unwrapped).config.features}
        by_split = {split: OneShotLearned(oneshot.policy, make_env(ONE_STEP_ENV, tune_kwargs, split=split))
                    for split in ("train", "val")}
        val_env = make_env(RETUNE_ENV, env_kwargs, split="val")
        return cls({**by_split, "test": oneshot}, val_env, val_episodes(val_env, n_val))


def fit_window_regressors(train_env: gym.Env, args: argparse.Namespace, anchors: Anchors | None
                          ) -> tuple[list[WindowRegressorPolicy], list[AnchoredWindowPolicy], dict[str, dict[float, float]]]:
    """``--fit-seeds`` window regressors (bboxtune.agents.evaluation.window_regressor), each on its own ``--train-episodes`` train
    episodes, as ``window_amortised`` policies (with ``--regime-informed`` each followed by the same fit told the true
    schedule, bboxtune.agents.evaluation.regime_informed); with ``anchors`` also as ``window_anchored`` policies and, from a
    second regressor on the same episodes, ``window_residual`` policies (both anchored on the test split), each with
    the margin ``--anchor-margin`` or the one chosen on the val episodes (each margin's mean log-ratio on them: the
    third item)."""
    amortised, anchored, val_means = [], [], {}
    for k in range(args.fit_seeds):
        seed = args.seed + k
        suffix = "" if args.fit_seeds == 1 else f"_s{seed}"
        noise_seeds = train_seeds(np.random.default_rng(seed), args.train_episodes)
        start = time.perf_counter()
        regressor, candidates = fit_regressor(train_env, noise_seeds, seed=seed,
                                              anchor=anchors.by_split["train"] if anchors else None, progress=True)
        amortised.append(WindowRegressorPolicy(regressor, candidates, name=WINDOW_AMORTISED + suffix))
        print(f"fitted {amortised[-1].name} on {args.train_episodes} train episodes in {time.perf_counter() - start:.0f} s")
        if args.regime_informed:
            start = time.perf_counter()
            amortised.append(RegimeInformedPolicy.fit(RegimeObservation(train_env), noise_seeds, seed=seed,
                                                      name=WINDOW_REGIME_INFORMED + suffix, progress=True))
            print(f"fitted {amortised[-1].name} on the same episodes in {time.perf_counter() - start:.0f} s")
        if anchors is None:
            continue
        start = time.perf_counter()
        residual = fit_regressor(train_env, noise_seeds, seed=seed, anchor=anchors.by_split["train"], residual=True,
                                 progress=True)
        print(f"fitted {WINDOW_RESIDUAL}{suffix} on {args.train_episodes} train episodes in {time.perf_counter() - start:.0f} s")
        for name, (fitted, actions), around_anchor in ((WINDOW_ANCHORED, (regressor, candidates), False),
                                                       (WINDOW_RESIDUAL, residual, True)):
            policy = AnchoredWindowPolicy(fitted, actions, anchors.by_split["val"], margin=0.0, name=name + suffix,
                                          around_anchor=around_anchor)
            margin = args.anchor_margin
            if margin is None:
                start = time.perf_counter()
                margin, val_means[policy.name] = select_margin(policy, anchors.val_env, anchors.val_episodes,
                                                               WindowRegressorSettings().margins)
                print(f"{policy.name}: margin {margin} chosen on {len(anchors.val_episodes)} val episodes "
                      f"({time.perf_counter() - start:.0f} s): {val_means[policy.name]}")
            anchored.append(policy.with_anchor(anchors.by_split["test"], margin))
    return amortised, anchored, val_means


def anchored_settings(anchored: list[AnchoredWindowPolicy], val_means: dict[str, dict[float, float]],
                      anchors: Anchors, around_anchor: bool) -> str:
    """summary.md's line on the ``window_anchored`` (or, with ``around_anchor``, ``window_residual``) policies: their
    candidates, margins and how the margins were chosen."""
    policies = [p for p in anchored if p.around_anchor == around_anchor]
    if around_anchor:
        settings = WindowRegressorSettings()
        what = (f"a second regressor on the same episodes whose candidates are `oneshot_learned`'s action moved by "
                f"{len(policies[0].candidates)} offsets ({settings.residual_points} per dimension in "
                f"±{settings.residual_step:g}, clipped to the action box), its input the observation and that action")
    else:
        what = "the same regressor(s), anchored at `oneshot_learned`'s action"
    chosen = ", ".join(f"{p.name} {p.margin:g}" for p in policies)
    if not val_means:
        return f"{what}; margin (--anchor-margin): {chosen}"
    tried = "; ".join(f"{p.name}: " + ", ".join(f"{m:g} {v:+.3f}" for m, v in val_means[p.name].items()) for p in policies)
    return (f"{what}; margin chosen on {len(anchors.val_episodes)} val-split episodes: {chosen} (mean log-ratio vs "
            f"rule there per margin — {tried})")


def compare_retune(args: argparse.Namespace, cfg: dict[str, Any], envs_and_kwargs: tuple[gym.Env, gym.Env, dict[str, Any]],
                   episodes_described: tuple[list[EpisodeSpec], str],
                   models: tuple[list[SB3Policy], dict[str, list[str]], str], oneshot: OneShotLearned | None, out: Path,
                   command: str) -> Path:
    """The FilterRetune-v0 comparison (bboxtune.agents.evaluation.retune_eval) of compare.py's parsed ``args``: the
    test env, the train
    env (the regressors' episodes) and their kwargs, the test episodes with their description for summary.md, the
    run(s)' models with their groups across training seeds and description, and ``--oneshot-model``; writes
    results.csv, summary.md and the figures in ``out``."""
    env, train_env, env_kwargs = envs_and_kwargs
    episodes, described = episodes_described
    learned, groups, models_described = models
    config = cast("FilterRetuneEnv", env.unwrapped).config
    search = GridSearch(budget=args.oracle_budget)
    scored = f"{cfg['algo']} from {args.model}" if learned else "no trained tuner (no --model)"
    print(f"seed: {args.seed}\n{scored}: {RETUNE_ENV} {env_kwargs}, {len(episodes)} {args.split} episodes, "
          f"window {config.window}")
    anchors = Anchors.build(oneshot, env_kwargs, args.val_episodes) if oneshot else None
    regressors, anchored, val_means = fit_window_regressors(train_env, args, anchors)
    online = [OneShotLearned(oneshot.policy, oneshot.tune_env, online=True)] if oneshot else []
    methods = [Sequential(RulePolicy()), OneShotOracle(search), *([oneshot] if oneshot else []), *online,
               window_oracle(search), *([RegimeOracle(search)] if args.regime_informed else []),
               *(Sequential(p) for p in [*regressors, *anchored, *learned])]
    sequential = [p.name for p in [*regressors, *anchored, *learned]]
    start = time.perf_counter()
    result = evaluate_retune(env, methods, episodes, progress=True)
    print(f"scored {len(result.truth_at_test)} methods on {len(episodes)} episodes in {time.perf_counter() - start:.0f} s")
    write_results_csv(out / "results.csv", result.rows)
    title = (f"{cfg['algo'] if learned else 'window tuners'} vs baselines · {RETUNE_ENV} · backend {config.backend} · "
             f"source {config.source}")
    gain_boxplot(out / "gain_boxplot.png", by_method(result.rows, "log_ratio"), title)
    ex = result.example
    plotted = ("rule", ONESHOT_ORACLE, WINDOW_ORACLE, regressors[0].name, *(p.name for p in anchored[:2]),
               *(p.name for p in learned[:1]))
    shown = {k: v for k, v in ex["schedules"].items() if k in plotted}
    parameter_schedule(out / "parameter_schedule.png", shown, ex["scenario"], f"{title}\ntest episode 0")
    settings_md = {"command": f"`{command}`", "model": models_described,
                   "oneshot_learned": (f"`{args.oneshot_model}` (its final model)" if oneshot
                                       else "not scored (no --oneshot-model)"),
                   "inputs held at their training value": describe_held_features(
                       {**{p.name: p.normalizer for p in learned},
                        **({ONESHOT_LEARNED: oneshot.policy.normalizer} if oneshot and isinstance(oneshot.policy, SB3Policy)
                           else {})},
                       {p.name: cast("FilterRetuneEnv", env.unwrapped).observation_names for p in learned}),
                   WINDOW_AMORTISED: f"{', '.join(p.name for p in regressors if not isinstance(p, RegimeInformedPolicy))}: "
                                     f"per-window regressor(s) "
                                     f"(bboxtune.agents.evaluation.window_regressor, {len(regressors[0].candidates)} "
                                     f"candidate actions) fitted on {args.train_episodes} train-split episodes each "
                                     f"(seeds {args.seed} … "
                                     f"{args.seed + args.fit_seeds - 1})"
                                     + (f"; its candidates include the `oneshot_learned` action (the anchor of "
                                        f"{WINDOW_ANCHORED})" if anchors else ""),
                   **({WINDOW_REGIME_INFORMED: "a reference that uses the truth: the same fit on the same episodes "
                                               "with the true regime schedule around each window after the observation "
                                               "(bboxtune.agents.evaluation.regime_informed, --regime-informed)",
                       REGIME_ORACLE: "in every window of a true regime state (noise regime × manoeuvre × gap, the "
                                      "window's majority) the action with the lowest squared error over that state's "
                                      "windows, with the truth, searched as the oracles "
                                      "(bboxtune.agents.evaluation.regime_informed)"}
                      if args.regime_informed else {}),
                   **({WINDOW_ANCHORED: anchored_settings(anchored, val_means, anchors, around_anchor=False),
                       WINDOW_RESIDUAL: anchored_settings(anchored, val_means, anchors, around_anchor=True)} if anchors else {}),
                   "env": f"`{env_kwargs}`",
                   "test episodes": described,
                   "scored frames": f"every frame after the warm-up window (the first {config.window}, filtered by the rule "
                                    "for every filter method)",
                   "oracles": f"grid of <= {search.budget} actions, then {search.rounds} local refinements, with the truth: "
                              f"{ONESHOT_ORACLE} one action for the whole track, {WINDOW_ORACLE} greedily per window"}
    summary = summary_markdown(result.rows, result.truth_at_test, learned=sequential, title=title,
                               settings=settings_md, figures=["gain_boxplot.png", "parameter_schedule.png"],
                               n_boot=args.bootstrap, seed=args.seed, rmse_oracle=WINDOW_ORACLE)
    if args.fit_seeds > 1:
        groups = {**groups, **{name: [p.name for p in regressors if p.name.startswith(name)]
                               for name in (WINDOW_AMORTISED, WINDOW_REGIME_INFORMED) if args.regime_informed
                               or name == WINDOW_AMORTISED}}
        groups.update({name: [p.name for p in anchored if p.name.startswith(name)]
                       for name in (WINDOW_ANCHORED, WINDOW_RESIDUAL) if anchored})
    head, figures = summary.split("## Figures")
    seeds = seeds_section(result.rows, groups, n_boot=args.bootstrap, seed=args.seed,
                          reference=[m for m in ("raw", "rule", ONESHOT_LEARNED, ONESHOT_ORACLE, WINDOW_ORACLE)
                                     if m in result.truth_at_test]) if groups else ""
    summary = head + "\n".join(retune_tables(result.rows, sequential, args.bootstrap, args.seed)) + "\n" + seeds + \
        "\n## Figures" + figures
    write_text_atomic(out / "summary.md", summary)
    print(summary.split("## Paired")[0])
    print(f"wrote {out}")
    return out
