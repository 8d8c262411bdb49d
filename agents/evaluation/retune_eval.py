"""Score re-tuning policies of ``bboxtune/FilterRetune-v0`` against one-shot and per-window baselines.

Every method plays each test episode from the same reset (pinned options, common random numbers); the first
window is the env's warm-up, filtered by the rule for every filter method, so every method is scored on the
frames after it, [W, T) (W = ``window``; the raw measurements and the adaptive KF on the same frames). Methods
(names as in ``results.csv``):

* ``raw`` — the measurements themselves (no filter; missing frames scored as missing estimates, as in
  :mod:`bboxtune.agents.evaluation.evaluate`);
* ``rule`` — the fixed rule in every window (the env's reference: log-ratio 0);
* ``oneshot_oracle`` — the best single action held for the whole track (grid search with the truth over
  ``env.unwrapped.score_rest``, the rule's action a candidate);
* ``oneshot_learned`` — a FilterTune-v0 model's action (its observation of the whole track, from a
  FilterTune-v0 env with the same arguments reset to the same episode), held for the whole track: offline, it
  knows the future (later gaps, manoeuvres, regimes) when it decides;
* ``oneshot_learned_online`` — the same model deciding once from the warm-up window only (what exists when the
  filter starts behind a live tracker), held for the rest;
* ``window_oracle`` — greedy per-window search with the truth: in each window the action maximising the step's
  reward (with the default ``retune_reward="track"``: the reward of the track so far), carrying the filter
  state (``env.unwrapped.score``);
* ``adaptive`` — the Sage–Husa innovation-adaptive KF (:mod:`bboxtune.agents.policies.adaptive`), no tuning, no truth;
* ``imm`` — an IMM over two KF tunings (the nominal σ_w and 10 × it, :mod:`bboxtune.agents.policies.imm`), no tuning, no truth;
* ``window_amortised`` — a learned sequential tuner without RL: per window, the candidate whose log RMSE on the
  coming window a regressor of the observation predicts lowest (:mod:`bboxtune.agents.evaluation.window_regressor`,
  fitted on train
  episodes by ``scripts/compare.py``), played with :class:`Sequential`;
* the trained sequential tuner (named by its algorithm, e.g. ``ppo``).

Per method and episode: RMSE (px) over the scored frames, success AUC, precision@20, and the log-ratio
log(RMSE_rule / RMSE) — the same records as :mod:`bboxtune.agents.evaluation.evaluate`, so
:mod:`bboxtune.agents.evaluation.report` writes the tables.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from bboxtune.agents.evaluation.evaluate import ADAPTIVE, RAW, TRUE_KEYS
from bboxtune.agents.policies.adaptive import SageHusaConfig, sage_husa_positions
from bboxtune.agents.policies.baselines import GridSearch, OraclePolicy, Policy, RulePolicy
from bboxtune.agents.policies.imm import IMMConfig, imm_positions
from bboxtune.agents.splits import EpisodeSpec
from bboxtune.envs.episodes.scoring import score_estimates

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.episodes.episode import Episode
    from bboxtune.envs.retune_env import FilterRetuneEnv
    from bboxtune.envs.tune_env import FilterTuneEnv

ONESHOT_ORACLE, WINDOW_ORACLE, ONESHOT_LEARNED = "oneshot_oracle", "window_oracle", "oneshot_learned"
ONESHOT_LEARNED_ONLINE = "oneshot_learned_online"
IMM = "imm"
# the default settings (frozen dataclasses: one shared instance each, as a call in the default would be)
DEFAULT_SEARCH, DEFAULT_ADAPTIVE, DEFAULT_IMM = GridSearch(), SageHusaConfig(), IMMConfig()


class RetuneMethod(ABC):
    """Plays an episode of a FilterRetune-v0 env from its reset to the end."""

    name: str = ""
    truth_at_test: str = "n"

    @abstractmethod
    def play(self, env: gym.Env, obs: np.ndarray) -> list[dict[str, Any]]:
        """Step ``env`` (just reset, observation ``obs``) to the episode's end; the steps' ``info`` dicts."""


class Sequential(RetuneMethod):
    """A policy asked again in every window (``policy.act(obs, env)`` with the window's observation)."""

    def __init__(self, policy: Policy, name: str | None = None, truth_at_test: str | None = None) -> None:
        self.policy = policy
        self.name = name or policy.name
        self.truth_at_test = truth_at_test or policy.truth_at_test

    def play(self, env: gym.Env, obs: np.ndarray) -> list[dict[str, Any]]:
        infos, done = [], False
        self.policy.begin_episode()
        while not done:
            obs, _, done, _, info = env.step(self.policy.act(obs, env))
            infos.append(info)
        return infos


class OneShot(RetuneMethod):
    """One action chosen at the first window and held for the rest of the track."""

    def play(self, env: gym.Env, obs: np.ndarray) -> list[dict[str, Any]]:
        action = self.choose(obs, env)
        infos, done = [], False
        while not done:
            _, _, done, _, info = env.step(action)
            infos.append(info)
        return infos

    @abstractmethod
    def choose(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        """The action (d,) held for the whole track."""


class OneShotOracle(OneShot):
    """The best single action for the rest of the track, searched with the truth."""

    name, truth_at_test = ONESHOT_ORACLE, "y (truth)"

    def __init__(self, search: GridSearch = DEFAULT_SEARCH) -> None:
        self.oracle = OraclePolicy(search, anchors=(RulePolicy(),))

    def choose(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        base = cast("FilterRetuneEnv", env.unwrapped)
        return self.oracle.episode_search(base.score_rest, cast("Episode", base.episode), base.action_map,
                                          base.config.backend)  # base.episode: set by the env's reset


class OneShotLearned(OneShot):
    """A one-step (FilterTune-v0) tuner: it observes the whole track in ``tune_env`` (same arguments, reset to the
    same episode) and its action is held for the whole track — offline smoothing, where the whole track is known
    before the filter runs. ``online=True`` (``oneshot_learned_online``): it observes only what exists when the
    filter starts, the warm-up window (its FilterTune-v0 features computed on those frames), as a filter behind
    a live tracker would."""

    def __init__(self, policy: Policy, tune_env: gym.Env, online: bool = False) -> None:
        self.policy = policy
        self.tune_env = tune_env
        self.online = online
        self.name = ONESHOT_LEARNED_ONLINE if online else ONESHOT_LEARNED

    def choose(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        base = cast("FilterRetuneEnv", env.unwrapped)
        if self.online:  # the FilterTune-v0 features of the frames seen so far; no whole-track episode needed
            tune_obs = base.features_so_far(msd=cast("FilterTuneEnv", self.tune_env.unwrapped).config.features == "msd")
        else:
            ep = cast("Episode", base.episode)  # set by the env's reset
            options = {k: ep.meta[k] for k in ("noise_seed", "sequence", "tracker") if ep.meta.get(k) not in (None, "")}
            tune_obs, _ = self.tune_env.reset(options=options)
        self.policy.begin_episode()
        return self.policy.act(tune_obs, self.tune_env)


def window_oracle(search: GridSearch = DEFAULT_SEARCH) -> Sequential:
    """Greedy per-window search with the truth (the filter state carried)."""
    return Sequential(OraclePolicy(search, anchors=(RulePolicy(),)), name=WINDOW_ORACLE, truth_at_test="y (truth, per window)")


@dataclass
class RetuneEvaluation:
    """Per-episode records and one episode's parameter schedule per method, for the plots."""

    rows: list[dict[str, Any]]
    truth_at_test: dict[str, str]
    example: dict[str, Any]  # episode 0: truth, y, estimates, per-method window params, the true schedule


def evaluate_retune(env: gym.Env, methods: Sequence[RetuneMethod], episodes: Sequence[EpisodeSpec], *,
                    adaptive: SageHusaConfig | None = DEFAULT_ADAPTIVE, imm: IMMConfig | None = DEFAULT_IMM,
                    progress: bool = False) -> RetuneEvaluation:
    """Play every method on every episode and score the frames after the warm-up window (``adaptive`` / ``imm``
    None: leave that estimator out)."""
    base = cast("FilterRetuneEnv", env.unwrapped)
    names = [RAW, *(m.name for m in methods), *([ADAPTIVE] if adaptive is not None else []), *([IMM] if imm is not None else [])]
    if len(set(names)) != len(names) or "rule" not in names:
        raise ValueError(f"method names {names} must be distinct and include 'rule'")
    if not episodes:
        raise ValueError("no episodes to evaluate")
    rows: list[dict[str, Any]] = []
    example: dict[str, Any] = {}
    for i, spec in enumerate(tqdm(episodes, desc="test episodes", disable=not progress)):
        estimates, schedules = [], {}
        for method in methods:
            obs, _ = env.reset(options=spec.options())
            infos = method.play(env, obs)
            estimates.append(base.estimates)
            schedules[method.name] = [(info["window"], info["params"]) for info in infos]
        ep = cast("Episode", base.episode)  # set by the resets above
        warm = min(base.config.window, len(ep.y))  # the first frame after the warm-up window
        est = [ep.y, *estimates]
        if adaptive is not None:
            est.append(sage_husa_positions(ep.y[None], ep.tau, ep.nominal.sigma_w, ep.nominal.sigma_v, adaptive)[0])
        if imm is not None:
            est.append(imm_positions(ep.y[None], ep.tau, ep.nominal.sigma_w, ep.nominal.sigma_v, imm)[0])
        est_all = np.stack(est)
        scores = score_estimates(est_all[:, warm:], ep.truth[warm:])
        rule_rmse = float(scores["rmse"][names.index("rule")])
        with np.errstate(divide="ignore", invalid="ignore"):
            log_ratio = np.log(rule_rmse / scores["rmse"])
        known = {**ep.meta, **ep.scenario}
        truth = {k: known[k] for k in TRUE_KEYS if k in known}
        where = {"sequence": ep.meta.get("sequence") or "", "tracker": ep.meta.get("tracker") or ""}
        for j, name in enumerate(names):
            rows.append({"method": name, "episode": i, **where, "rmse": float(scores["rmse"][j]),
                         "success_auc": float(scores["success_auc"][j]), "precision20": float(scores["precision20"][j]),
                         "backend": base.config.backend, "source": ep.meta.get("source", base.config.source),
                         "noise_seed": int(spec.noise_seed), "rule_rmse": rule_rmse, "log_ratio": float(log_ratio[j]),
                         "iou_mean": float(scores["iou_mean"][j]), "iou_precision": float(scores["iou_precision"][j]),
                         "scored_from": warm, **{f"true_{k}": v for k, v in truth.items()}})
        if i == 0:
            example = {"truth": ep.truth, "y": ep.y, "estimates": dict(zip(names, est_all, strict=False)), "schedules": schedules,
                       "scenario": dict(ep.scenario), "tau": ep.tau, "warm": warm}
    truth_at_test = {RAW: "n", **{m.name: m.truth_at_test for m in methods}}
    truth_at_test.update({name: "n" for name in (ADAPTIVE, IMM) if name in names})
    return RetuneEvaluation(rows=rows, truth_at_test=truth_at_test, example=example)
