"""Fit the baselines on train episodes and score every method on the same test episodes.

Each test episode (an :class:`bboxtune.agents.splits.EpisodeSpec`, from :func:`evaluation_episodes`) is reset once with its
pinned options; every policy chooses its action for it and each action is scored by ``env.unwrapped.score``
(one call per action, so a method's scores never depend on which other methods are compared). Two methods are
estimates of their own, scored on the same measurements with ``bboxtune.envs.episodes.scoring.score_estimates``: ``raw``, the
measurements themselves (no filter), the box Kalman filters trackers ship with their published settings
(:data:`PEERS`: ``bytetrack_kf``, ByteTrack / DeepSORT's, and ``sort_kf``, SORT's; :mod:`bboxtune.filters.bytetrack_kf`,
:mod:`bboxtune.filters.sort_kf`), and the Sage–Husa adaptive KF (:mod:`bboxtune.agents.policies.adaptive`). So all methods see
identical data
(common random numbers).

A policy that leaves an episode alone (``Policy.leaves_alone``: the gated tuners of
:mod:`bboxtune.agents.evaluation.gate`) is scored
there on the measurements themselves, exactly as ``raw``, with NaN parameters.

``raw`` and missing measurements: a frame without a measurement (a NaN row of ``y``, e.g. a tracker that lost
the target) is a missing estimate, scored as the scorer scores any missing estimate — a failure for success
AUC and precision (IoU 0, infinite centre error) and left out of the RMSE (which then covers the frames that
have a measurement; the filters predict through such gaps and are scored there).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from bboxtune import filters
from bboxtune.agents.episodes import EpisodeBank
from bboxtune.agents.policies.adaptive import SageHusaConfig, sage_husa_positions
from bboxtune.agents.policies.baselines import (
    AmortisedPolicy,
    EpisodePolicy,
    GlobalPolicy,
    GridSearch,
    OraclePolicy,
    Policy,
    RuleEstimatedSigmaPolicy,
    RulePolicy,
    RuleTrueSigmaPolicy,
    sets_sigma_rule,
)
from bboxtune.agents.splits import EpisodeSpec, otb_episodes, split_seeds, train_seeds
from bboxtune.envs.data import metrics
from bboxtune.envs.data.boxes import cxcywh_to_xywh
from bboxtune.envs.data.memory import check_fits
from bboxtune.envs.episodes.actions import parameter_family
from bboxtune.envs.episodes.scoring import detections, score_estimates

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.episodes.episode import Episode
    from bboxtune.envs.episodes.sources import OTBSource
    from bboxtune.envs.track_env import TrackEnv
    from bboxtune.envs.tune_env import FilterTuneEnv

RAW = "raw"
PEERS = ("bytetrack_kf", "sort_kf")  # the practitioners' box filters, stock settings, scored beside every tuner
ADAPTIVE = "adaptive"
ADAPTIVE_TRUTH = "n"
DEFAULT_ADAPTIVE = SageHusaConfig()  # the adaptive KF's default settings (frozen: one shared instance)
OTB_SOURCES = ("otb", "otb_tracker")  # sources whose test episodes are enumerated, not drawn
TRUE_KEYS = ("psi", "sigma_w", "sigma_xi", "sigma_rel", "tau")  # the true scenario, for analysis (true_<key>)
# Memory an evaluation keeps per episode (tracemalloc over the records of 13 methods, results.csv and summary.md: 91 kB
# per episode with 2000 bootstrap resamples, 32 kB with 200): its spec and noise seed, per method its record and the
# summary's copies of it (~2.2 kB) and per bootstrap resample its index and the resampled statistics (~31 B), each
# with a margin (the estimate is 1.1-1.2 times the peak: tests/agents/evaluation/test_evaluation_memory.py)
SPEC_BYTES = 128
MAX_BASELINES = 11  # methods besides the learned ones: raw, the two PEERS, adaptive, <= 5 standard_policies, 2 fitted
RECORD_BYTES = 2500
RESAMPLE_BYTES = 36


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


def standard_policies(source: str, search: GridSearch, reward: str = "rmse", *, backend: str) -> list[Policy]:
    """The training-free policies: rule, rule with estimated σ, rule with true σ (sim only; both σ rules only for
    back ends they apply to, ``bboxtune.agents.policies.baselines.sets_sigma_rule``: not ``bytetrack_kf``), the oracle of the
    env's ``reward`` (named ``oracle``) and the oracle of the other metric (``oracle_auc``, maximising success AUC,
    when the reward is RMSE; else ``oracle_rmse``); both searches (``search``) are anchored at the rules' actions,
    so that each is never worse than any rule on its objective."""
    rules: list[EpisodePolicy] = [RulePolicy()]
    if sets_sigma_rule(backend):
        rules.append(RuleEstimatedSigmaPolicy())
        if source == "sim":
            rules.append(RuleTrueSigmaPolicy())
    other = (OraclePolicy(search, anchors=rules, objective="success_auc", name="oracle_auc") if reward == "rmse"
             else OraclePolicy(search, anchors=rules, objective="rmse", name="oracle_rmse"))
    return [*rules, OraclePolicy(search, anchors=rules), other]


def evaluation_episodes(env: gym.Env, split: str, *, episodes: int | None, seeds_per_sequence: int | None,
                  seed: int = 0) -> list[EpisodeSpec]:
    """The episodes an evaluation of ``env`` (built with ``split``) scores. OTB sources enumerate them
    (:func:`bboxtune.agents.splits.otb_episodes` over ``env.unwrapped.source.sequences`` and ``.trackers``, each tracker on
    the sequences it has output for, ``.sequences_of``;
    ``seeds_per_sequence`` for "otb", ``episodes`` must be None); the others take ``episodes`` noise seeds of
    :func:`bboxtune.agents.splits.split_seeds` (``seeds_per_sequence`` must be None). ValueError naming the argument."""
    base = cast("TrackEnv", env.unwrapped)
    source = base.config.source
    if source not in OTB_SOURCES:
        if episodes is None or seeds_per_sequence is not None:
            raise ValueError(f"source {source!r} draws its episodes: give their number, not seeds per sequence")
        return [EpisodeSpec(int(s)) for s in split_seeds(split, episodes, seed)]
    if episodes is not None:
        raise ValueError(f"source {source!r} enumerates its episodes (every sequence of the split"
                         f"{' × tracker' if source == 'otb_tracker' else ' × noise seeds'}): no episode count")
    pool = cast("OTBSource", base.source)  # an OTB source: source is one of OTB_SOURCES here
    if source == "otb":
        return otb_episodes(pool.sequences, (), split, seeds_per_sequence=seeds_per_sequence or 1, seed=seed)
    if seeds_per_sequence is not None:
        raise ValueError("source 'otb_tracker' replays each tracker's output once per sequence: no seeds per sequence")
    outputs = {t: set(pool.sequences_of(t)) for t in pool.trackers}
    return otb_episodes(pool.sequences, pool.trackers, split, seed=seed,
                        has_output=lambda tracker, sequence: sequence in outputs[tracker])


def check_evaluation_memory(n_episodes: int, n_methods: int, n_boot: int, what: str) -> None:
    """``bboxtune.envs.data.memory.MemoryLimitError`` (a ``ValueError`` starting with ``what``, the request) when scoring
    ``n_methods`` methods on ``n_episodes`` episodes and summarising them with ``n_boot`` bootstrap resamples would
    need more memory than this machine has available."""
    check_fits(n_episodes * (SPEC_BYTES + n_methods * RECORD_BYTES + n_boot * RESAMPLE_BYTES),
               f"{what} ({n_episodes} episodes × {n_methods} methods, {n_boot} bootstrap resamples)")


def val_episodes(env: gym.Env, n: int, seeds_per_sequence: int = 1) -> list[EpisodeSpec]:
    """Validation episodes of ``env`` (built with split "val") to choose a setting on: ``n`` drawn episodes for sim
    and video sources, every val sequence × ``seeds_per_sequence`` noise seeds for "otb" and every val sequence ×
    tracker for "otb_tracker"."""
    source = cast("TrackEnv", env.unwrapped).config.source
    return evaluation_episodes(env, "val", episodes=None if source in OTB_SOURCES else n,
                               seeds_per_sequence=seeds_per_sequence if source == "otb" else None)


@dataclass
class Evaluation:
    """Per-episode records and the pieces the plots need."""

    rows: list[dict[str, Any]]  # one per method × episode
    success: dict[str, np.ndarray]  # method -> mean success curve over episodes (21,)
    precision: dict[str, np.ndarray]  # method -> mean precision curve (51,)
    example: dict[str, Any]  # the first episode: truth, y, estimates per method
    truth_at_test: dict[str, str]  # method -> "n" / "y (...)"


def evaluate(env: gym.Env, policies: Sequence[Policy], episodes: Sequence[EpisodeSpec], *,
             adaptive: SageHusaConfig | None = DEFAULT_ADAPTIVE, progress: bool = False) -> Evaluation:
    """Score ``raw``, ``policies`` and the adaptive KF (unless ``adaptive`` is None) on ``episodes``."""
    base = cast("FilterTuneEnv", env.unwrapped)
    backend, source = base.config.backend, base.config.source
    names = [RAW, *PEERS] + [p.name for p in policies] + ([ADAPTIVE] if adaptive is not None else [])
    if len(set(names)) != len(names) or "rule" not in names:
        raise ValueError(f"method names {names} must be distinct and include 'rule' (and not {RAW!r} or {PEERS})")
    if not episodes:
        raise ValueError("no episodes to evaluate")
    rows: list[dict[str, Any]] = []
    success = {n: np.zeros(len(metrics.SUCCESS_THRESHOLDS)) for n in names}
    precision = {n: np.zeros(len(metrics.PRECISION_THRESHOLDS)) for n in names}
    example: dict[str, Any] = {}
    for i, spec in enumerate(tqdm(episodes, desc="test episodes", disable=not progress)):
        obs, _ = env.reset(options=spec.options())
        ep = cast("Episode", base.episode)  # set by the reset
        for p in policies:
            p.begin_episode()
        actions = np.stack([p.act(obs, env) for p in policies])
        results = [None if p.leaves_alone(obs) else base.score(a[None]) for p, a in zip(policies, actions, strict=False)]
        peers = [filters.candidate_positions(peer, detections(peer, ep.y), ep.tau, {}) for peer in PEERS]
        estimates = [ep.y[None], *peers, *(ep.y[None] if r is None else r["estimates"] for r in results)]
        keys = parameter_family(backend)
        params = {k: np.array([np.nan] * (1 + len(PEERS)) + [np.nan if r is None else float(r["params"][k][0])
                                                            for r in results]) for k in keys}
        if adaptive is not None:
            estimates.append(sage_husa_positions(ep.y[None], ep.tau, ep.nominal.sigma_w, ep.nominal.sigma_v, adaptive))
            params = {k: np.append(v, np.nan) for k, v in params.items()}
        est = np.concatenate(estimates)
        scores = score_estimates(est, ep.truth)
        rule_rmse = float(scores["rmse"][names.index("rule")])
        with np.errstate(divide="ignore", invalid="ignore"):  # a NaN (raw: no measurement at all) or 0 RMSE
            log_ratio = np.log(rule_rmse / scores["rmse"])
        pred, gt = cxcywh_to_xywh(est), cxcywh_to_xywh(ep.truth)
        s_curve, p_curve = metrics.success_curve(pred, gt), metrics.precision_curve(pred, gt)
        known = {**ep.meta, **ep.scenario}  # identifying metadata and the true scenario (for analysis)
        meta = {k: known[k] for k in TRUE_KEYS if k in known}
        where = {"sequence": ep.meta.get("sequence", ""), "tracker": ep.meta.get("tracker", "")}
        for j, name in enumerate(names):
            success[name] += s_curve[j] / len(episodes)
            precision[name] += p_curve[j] / len(episodes)
            rows.append({
                "method": name, "episode": i, **where, "rmse": float(scores["rmse"][j]),
                "success_auc": float(scores["success_auc"][j]), "precision20": float(scores["precision20"][j]),
                "backend": backend, "source": ep.meta.get("source", source), "noise_seed": int(spec.noise_seed),
                "rule_rmse": rule_rmse, "log_ratio": float(log_ratio[j]),
                "iou_mean": float(scores["iou_mean"][j]), "iou_precision": float(scores["iou_precision"][j]),
                **{f"param_{k}": float(v[j]) for k, v in params.items()},
                **{f"true_{k}": v for k, v in meta.items()},
            })
        if i == 0:
            example = {"truth": ep.truth, "y": ep.y, "estimates": dict(zip(names, est, strict=False)), "meta": meta}
    truth = {RAW: "n", **{peer: "n" for peer in PEERS}, **{p.name: p.truth_at_test for p in policies}}
    if adaptive is not None:
        truth[ADAPTIVE] = ADAPTIVE_TRUTH
    return Evaluation(rows=rows, success=success, precision=precision, example=example, truth_at_test=truth)
