"""Fit the baselines on train episodes and score every method on the same test episodes.

Each test episode is reset once (``options={"noise_seed": …}``, test split of :mod:`agents.splits`); every
policy chooses its action for it, all actions are scored in one batched ``env.unwrapped.score`` call, and the
Sage–Husa adaptive KF (its own filter, :mod:`agents.adaptive`) is scored on the same measurements with
``envs.scoring.score_estimates``. So all methods see identical data (common random numbers).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from agents.adaptive import SageHusaConfig, sage_husa_positions
from agents.baselines import (AmortisedPolicy, EpisodePolicy, GlobalPolicy, GridSearch, OraclePolicy, Policy,
                              RuleEstimatedSigmaPolicy, RulePolicy, RuleTrueSigmaPolicy)
from agents.episodes import EpisodeBank
from agents.splits import train_seeds
from envs import metrics
from envs.boxes import cxcywh_to_xywh
from envs.scoring import score_estimates

ADAPTIVE = "adaptive"
ADAPTIVE_TRUTH = "n"


@dataclass(frozen=True)
class BaselineSettings:
    """How the trained baselines are fitted and how hard the oracle searches."""

    train_episodes: int = 1000  # train-split episodes for the amortised regressor (oracle targets)
    global_episodes: int = 300  # of those, the first ones scored by the global tuner's objective
    global_trials: int = 64  # Optuna TPE trials of the global tuner
    seed: int = 0


def fit_baselines(env: gym.Env, oracle: OraclePolicy, settings: BaselineSettings,
                  progress: bool = False) -> list[Policy]:
    """``global`` and ``amortised`` (regressing ``oracle``'s actions), fitted on train-split episodes of ``env``
    (an env whose ``split`` config is "train"); seeds from ``settings.seed``."""
    seeds = train_seeds(np.random.default_rng(settings.seed), settings.train_episodes)
    bank = EpisodeBank(env, seeds, progress=progress)
    glob = GlobalPolicy.fit(bank.head(settings.global_episodes), n_trials=settings.global_trials,
                            seed=settings.seed, progress=progress)
    targets = AmortisedPolicy.oracle_targets(bank, oracle, progress=progress)
    amortised = AmortisedPolicy.fit(bank.observations, targets, seed=settings.seed)
    return [glob, amortised]


def standard_policies(source: str, search: GridSearch) -> list[Policy]:
    """The training-free policies: rule, rule with estimated σ, rule with true σ (sim only), and the oracle
    (grid ``search`` anchored at the actions of all of them, so that it is never worse than any)."""
    rules: list[EpisodePolicy] = [RulePolicy(), RuleEstimatedSigmaPolicy()]
    if source == "sim":
        rules.append(RuleTrueSigmaPolicy())
    return [*rules, OraclePolicy(search, anchors=rules)]


@dataclass
class Evaluation:
    """Per-episode records and the pieces the plots need."""

    rows: list[dict[str, Any]]  # one per method × episode
    success: dict[str, np.ndarray]  # method -> mean success curve over episodes (21,)
    precision: dict[str, np.ndarray]  # method -> mean precision curve (51,)
    example: dict[str, Any]  # the first episode: truth, y, estimates per method
    truth_at_test: dict[str, str]  # method -> "n" / "y (...)"


def evaluate(env: gym.Env, policies: Sequence[Policy], seeds: Sequence[int], *,
             adaptive: SageHusaConfig | None = SageHusaConfig(), progress: bool = False) -> Evaluation:
    """Score ``policies`` (and the adaptive KF unless ``adaptive`` is None) on the episodes ``seeds``."""
    base = env.unwrapped
    backend = base.config.backend
    names = [p.name for p in policies] + ([ADAPTIVE] if adaptive is not None else [])
    if len(set(names)) != len(names) or "rule" not in names:
        raise ValueError(f"method names {names} must be distinct and include 'rule'")
    rows: list[dict[str, Any]] = []
    success = {n: np.zeros(len(metrics.SUCCESS_THRESHOLDS)) for n in names}
    precision = {n: np.zeros(len(metrics.PRECISION_THRESHOLDS)) for n in names}
    example: dict[str, Any] = {}
    for i, seed in enumerate(tqdm(seeds, desc="test episodes", disable=not progress)):
        obs, _ = env.reset(options={"noise_seed": int(seed)})
        ep = base.episode
        actions = np.stack([p.act(obs, env) for p in policies])
        res = base.score(actions)
        est = res["estimates"]
        scores = {k: v for k, v in res.items() if k not in ("params", "estimates")}
        params = {k: np.asarray(v, dtype=float) for k, v in res["params"].items()}
        if adaptive is not None:
            a_est = sage_husa_positions(ep.y[None], ep.tau, ep.nominal.sigma_w, ep.nominal.sigma_v, adaptive)
            a_scores = score_estimates(a_est, ep.truth)
            est = np.concatenate([est, a_est])
            scores = {k: np.append(scores[k], a_scores[k][0]) for k in a_scores}
            params = {k: np.append(v, np.nan) for k, v in params.items()}
        rule_rmse = float(scores["rmse"][names.index("rule")])
        pred, gt = cxcywh_to_xywh(est), cxcywh_to_xywh(ep.truth)
        s_curve, p_curve = metrics.success_curve(pred, gt), metrics.precision_curve(pred, gt)
        known = {**ep.meta, **ep.scenario}  # identifying metadata and the true scenario (for analysis)
        meta = {k: known[k] for k in ("sequence", "psi", "sigma_w", "sigma_xi", "sigma_rel", "tau") if k in known}
        for j, name in enumerate(names):
            success[name] += s_curve[j] / len(seeds)
            precision[name] += p_curve[j] / len(seeds)
            rows.append({
                "method": name, "backend": backend, "episode": i, "noise_seed": int(seed),
                "rmse": float(scores["rmse"][j]), "rule_rmse": rule_rmse,
                "log_ratio": float(np.log(rule_rmse / scores["rmse"][j])),
                "success_auc": float(scores["success_auc"][j]), "precision20": float(scores["precision20"][j]),
                "iou_mean": float(scores["iou_mean"][j]), "iou_precision": float(scores["iou_precision"][j]),
                **{f"param_{k}": float(v[j]) for k, v in params.items()},
                **{f"true_{k}": v for k, v in meta.items()},
            })
        if i == 0:
            example = {"truth": ep.truth, "y": ep.y, "estimates": dict(zip(names, est)), "meta": meta}
    truth = {p.name: p.truth_at_test for p in policies}
    if adaptive is not None:
        truth[ADAPTIVE] = ADAPTIVE_TRUTH
    return Evaluation(rows=rows, success=success, precision=precision, example=example, truth_at_test=truth)
