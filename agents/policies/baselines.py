"""Non-learned tuners behind one small policy interface, scored on the same episodes as the learned ones.

A policy maps the env's current episode to an action in [-1, 1]^d (``bboxtune.envs.episodes.actions.ActionMap``):
``act(obs, env) -> (d,)``. Observation-only policies (:class:`ObsPolicy`: ``global``, ``amortised``, the
trained SB3 model) use ``obs`` alone and also offer a batched ``predict(obs (n, F)) -> (n, d)``; the others
read the episode through ``env.unwrapped`` (``episode``, ``action_map``, ``score``):

| name              | what it sets                                                     | ground truth at test |
|-------------------|------------------------------------------------------------------|----------------------|
| ``rule``          | the env's nominal parameters (N = N_opt(σ_v,nom, σ_w,nom, τ), ψ = nominal ψ) | no     |
| ``rule_est_sigma``| the rule with σ̂_v, σ̂_w estimated from the measurements          | no                   |
|                   | (``bboxtune.envs.episodes.features.estimate_sigmas``)            |                      |
| ``rule_true_sigma``| the rule with the scenario's true ψ, σ_w, σ (sim only; see the class) | true scenario |
| ``oracle``        | grid search + refinement on the env's reward with this episode's truth (the ceiling) | yes |
| ``oracle_auc`` / ``oracle_rmse`` | the same search maximising success AUC / minimising RMSE (the other metric's ceiling) | yes |
| ``global``        | one action for every episode, tuned with Optuna TPE on train episodes | no             |
| ``amortised``     | a regressor from the observation to the oracle's action, fitted on train episodes | no   |

The σ rules set ψ, N, σ_w, σ_v (``bboxtune.envs.episodes.actions.SIGMA_PARAMETERS``): a back end with other parameters
(``bytetrack_kf``, whose noise weights are relative to the box height; :func:`sets_sigma_rule`) has none, and
they refuse its actions (``ValueError``); its ``rule`` is stock ByteTrack.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import product
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
import optuna
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from tqdm import tqdm

from bboxtune.agents.episodes import EpisodeBank, ScoreFn, nominal_action
from bboxtune.envs.episodes.actions import SIGMA_PARAMETERS, ActionMap, Nominal, parameter_family
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.features import estimate_sigmas
from bboxtune.filters.horizon import rule_horizon

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.track_env import TrackEnv
    from bboxtune.envs.tune_env import FilterTuneEnv

CMN_BACKENDS = frozenset({"kf_cmn", "ufir_cmn"})  # back ends whose sigma_v is σ_ξ of the CMN


def sets_sigma_rule(backend: str) -> bool:
    """Whether the σ rules (rule_est_sigma, rule_true_sigma) apply to ``backend``: its parameters are ψ, N, σ_w, σ_v
    (``bboxtune.envs.episodes.actions.SIGMA_PARAMETERS``), not bytetrack_kf's weights."""
    return parameter_family(backend) == SIGMA_PARAMETERS


class Policy(ABC):
    """Chooses the action for the env's current episode."""

    name: str = ""
    truth_at_test: str = "n"  # does it use ground truth on the test episode? "n" or "y (what)"

    @abstractmethod
    def act(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        """Action (d,) for the episode ``env`` was just reset to; ``obs`` its observation."""

    # an optional hook, not abstract: the policies without a memory (most of them) keep this no-op
    def begin_episode(self) -> None:  # noqa: B027
        """Called before an episode's first ``act`` (a policy with a memory forgets the last episode here)."""

    def leaves_alone(self, obs: np.ndarray) -> bool:
        """Whether the policy leaves this episode's measurements as they are (no filter; ``bboxtune.agents.evaluation.gate``): the
        evaluation then scores the measurements themselves, as it scores ``raw``, instead of the action."""
        return False


class ObsPolicy(Policy):
    """A policy of the observation only."""

    @abstractmethod
    def predict(self, obs: np.ndarray) -> np.ndarray:
        """Actions (n, d) for observations (n, n_features)."""

    def act(self, obs: np.ndarray, env: gym.Env | None = None) -> np.ndarray:
        return self.predict(np.asarray(obs)[None])[0]


class EpisodePolicy(Policy):
    """A policy of the episode itself (its measurements, nominal parameters or, for references, its truth)."""

    @abstractmethod
    def episode_action(self, ep: Episode, amap: ActionMap, backend: str) -> np.ndarray:
        """Action (d,) for episode ``ep`` under the action map ``amap`` of an env with back end ``backend``."""

    def act(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        base = cast("TrackEnv", env.unwrapped)
        return self.episode_action(cast(Episode, base.episode), base.action_map, base.config.backend)  # after reset


def _clipped_action(amap: ActionMap, nominal: Nominal, params: dict[str, float]) -> np.ndarray:
    """Action (d,) for physical ``params``, each first clipped to the action map's reachable range."""
    lo = amap.to_params(-np.ones(amap.dim), nominal)
    hi = amap.to_params(np.ones(amap.dim), nominal)
    clipped = {k: float(np.clip(v, lo[k][0], hi[k][0])) for k, v in params.items()}
    return amap.to_actions(clipped, nominal)[0]


def _rule_action(ep: Episode, amap: ActionMap, psi: float, sigma_w: float, sigma_v: float) -> np.ndarray:
    """The rule's action for given ψ, σ_w, σ_v: N = round(N_opt(σ_v, σ_w, τ)) within [K, N_max]; when the
    action does not set σ_v (ratio-only back ends) σ_w is scaled so that σ_w/σ_v is the intended ratio. An action
    that tunes anything else (``bytetrack_kf``'s weights) raises ``ValueError``."""
    other = [p for p in amap.tune if p not in SIGMA_PARAMETERS]
    if other:
        raise ValueError(f"the σ rules set {SIGMA_PARAMETERS}; this env tunes {other} (bytetrack_kf's noise weights "
                         "have no σ rule: its rule is the stock filter, 'rule')")
    nominal = ep.nominal
    horizon = rule_horizon(sigma_v, sigma_w, ep.tau, amap.K, max_horizon=amap.horizon_max)
    if "sigma_v" not in amap.tune:
        sigma_w, sigma_v = sigma_w * nominal.sigma_v / sigma_v, nominal.sigma_v
    params = {"psi": psi, "horizon": float(horizon), "sigma_w": sigma_w, "sigma_v": sigma_v}
    return _clipped_action(amap, nominal, params)


class RulePolicy(EpisodePolicy):
    """The fixed rule of the literature with the env's nominal parameters (reward 0 by construction)."""

    name = "rule"

    def episode_action(self, ep: Episode, amap: ActionMap, backend: str) -> np.ndarray:
        return nominal_action(amap, ep.nominal)


class RuleEstimatedSigmaPolicy(EpisodePolicy):
    """The rule with σ̂_v, σ̂_w estimated from this episode's measurements (moment estimates that assume
    white noise, ``bboxtune.envs.episodes.features.estimate_sigmas``), ψ at its nominal value. Deployable, no training."""

    name = "rule_est_sigma"

    def episode_action(self, ep: Episode, amap: ActionMap, backend: str) -> np.ndarray:
        sigma_v, sigma_w = cast("tuple[float, float]", estimate_sigmas(ep.y, ep.tau))  # one track: floats
        return _rule_action(ep, amap, ep.nominal.psi, sigma_w, sigma_v)


class RuleTrueSigmaPolicy(EpisodePolicy):
    """The rule informed with the simulated scenario's true parameters (an upper reference, sim only).

    Sets ψ = true ψ; σ_w = true σ_w (px/s²); σ_v = true σ_ξ for the CMN back ends (``kf_cmn``, ``ufir_cmn``:
    their σ_v is the std of the white noise driving the CMN) and the stationary CMN std σ_ξ/√(1 − ψ²) for
    the white-noise back ends; N = round(N_opt(σ_v, σ_w, τ)) with those σ, within [K, N_max]. Only the
    parameters in the env's ``tune`` are applied (the others stay nominal); values outside the action range
    are clipped to it. The size coordinates (w, h) have other noise levels than (cx, cy) in the simulator,
    so even this rule is not optimal for them."""

    name = "rule_true_sigma"
    truth_at_test = "y (true ψ, σ)"

    def episode_action(self, ep: Episode, amap: ActionMap, backend: str) -> np.ndarray:
        if "sigma_xi" not in ep.scenario:
            raise ValueError(f"rule_true_sigma needs a simulated episode (source 'sim'); its scenario has {sorted(ep.scenario)}")
        psi, sigma_w, sigma_xi = float(ep.scenario["psi"]), float(ep.scenario["sigma_w"]), float(ep.scenario["sigma_xi"])
        sigma_v = sigma_xi if backend in CMN_BACKENDS else sigma_xi / np.sqrt(1.0 - psi**2)
        return _rule_action(ep, amap, psi, sigma_w, sigma_v)


@dataclass(frozen=True)
class GridSearch:
    """Search of [-1, 1]^d: a grid of ``points(d)`` values per dimension (about ``budget`` candidates in all),
    then ``rounds`` refinements, each a grid of ``refine`` values per dimension spanning ± one previous spacing
    around the best so far (so the spacing halves each round when ``refine`` = 5). Extra candidates (e.g. the
    rule's action) join the first stage, so the result is never worse than any of them."""

    budget: int = 300  # candidates of the first stage (per episode)
    rounds: int = 2
    refine: int = 5  # points per dimension in a refinement round (3 for d >= 4)

    def points(self, d: int) -> int:
        """Grid values per dimension of the first stage: floor(budget^(1/d)), at least 3."""
        return max(3, int(np.floor(self.budget ** (1.0 / d) + 1e-9)))

    def search(self, score: ScoreFn, d: int, extra: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """Best action (d,) and its reward for ``score(actions (A, d)) -> {"reward": (A,)}``."""
        n = self.points(d)
        axis = np.linspace(-1.0, 1.0, n)
        cands = np.array(list(product(axis, repeat=d)))
        if extra is not None:
            cands = np.concatenate([cands, np.atleast_2d(extra)])
        rewards = score(cands)["reward"]
        best, best_r = cands[np.argmax(rewards)], float(np.max(rewards))
        spacing = 2.0 / (n - 1)
        m = self.refine if d < 4 else 3
        for _ in range(self.rounds):
            offsets = np.array(list(product(np.linspace(-spacing, spacing, m), repeat=d)))
            cands = np.clip(best + offsets, -1.0, 1.0)
            rewards = score(cands)["reward"]
            if np.max(rewards) > best_r:
                best, best_r = cands[np.argmax(rewards)], float(np.max(rewards))
            spacing *= 2.0 / (m - 1)
        return best, best_r


ORACLE_OBJECTIVES = ("reward", "rmse", "success_auc")


class OraclePolicy(Policy):
    """Per-episode search on the ground truth (``env.unwrapped.score``, batched): the ceiling.

    ``objective``: what it maximises — ``"reward"`` the env's reward, ``"rmse"`` −log RMSE, ``"success_auc"``
    the success AUC. The actions of the ``anchors`` (default: the rule) join the search's first stage, so the
    oracle is never worse than any of them on its objective."""

    truth_at_test = "y (truth)"

    def __init__(self, search: GridSearch = GridSearch(), anchors: Sequence[EpisodePolicy] = (RulePolicy(),), *,
                 objective: str = "reward", name: str = "oracle") -> None:
        if objective not in ORACLE_OBJECTIVES:
            raise ValueError(f"objective={objective!r}; allowed: {ORACLE_OBJECTIVES}")
        self.search = search
        self.anchors = tuple(anchors)
        self.objective = objective
        self.name = name

    def _maximised(self, score: ScoreFn) -> ScoreFn:
        """``score`` with its ``reward`` replaced by the oracle's objective."""
        if self.objective == "reward":
            return score
        if self.objective == "rmse":
            return lambda actions: {"reward": -np.log(np.maximum(score(actions)["rmse"], 1e-300))}
        return lambda actions: {"reward": score(actions)[self.objective]}

    def act(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        base = cast("FilterTuneEnv", env.unwrapped)
        return self.episode_search(base.score, cast(Episode, base.episode), base.action_map, base.config.backend)

    def episode_search(self, score: ScoreFn, ep: Episode, amap: ActionMap, backend: str) -> np.ndarray:
        """The oracle's action (d,) for episode ``ep`` scored by ``score``."""
        extra = np.stack([a.episode_action(ep, amap, backend) for a in self.anchors]) if self.anchors else None
        return self.search.search(self._maximised(score), amap.dim, extra=extra)[0]


class GlobalPolicy(ObsPolicy):
    """The same action for every episode: argmax of the mean reward over train episodes (Optuna TPE)."""

    name = "global"

    def __init__(self, action: np.ndarray) -> None:
        self.action = np.asarray(action, dtype=np.float64)

    def predict(self, obs: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.action, (len(obs), len(self.action))).copy()

    @classmethod
    def fit(cls, bank: EpisodeBank, *, n_trials: int = 64, batch: int = 8, seed: int = 0,
            progress: bool = False) -> GlobalPolicy:
        """Tune on ``bank``: TPE (constant liar, ``batch`` trials scored together on every episode; ``n_trials``
        is rounded up to a multiple of ``batch``; the first trial is the centre of the action box)."""
        d = bank.action_map.dim
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        sampler = optuna.samplers.TPESampler(seed=seed, constant_liar=True, n_startup_trials=min(16, n_trials))
        study = optuna.create_study(direction="maximize", sampler=sampler)
        study.enqueue_trial({f"a{j}": 0.0 for j in range(d)})  # the centre of the action box
        for _ in tqdm(range(0, n_trials, batch), desc="global (TPE)", disable=not progress, leave=False):
            trials = [study.ask() for _ in range(batch)]
            actions = np.array([[t.suggest_float(f"a{j}", -1.0, 1.0) for j in range(d)] for t in trials])
            for trial, value in zip(trials, bank.mean_reward(actions), strict=False):
                study.tell(trial, float(value))
        best = study.best_params
        return cls(np.array([best[f"a{j}"] for j in range(d)]))


class AmortisedPolicy(ObsPolicy):
    """Supervised regressor from the observation features to the oracle's action (an MLP with the same
    hidden layers as the RL policy, on standardised features), fitted on train episodes; predictions are
    clipped to [-1, 1]."""

    name = "amortised"

    def __init__(self, regressor: Any) -> None:
        self.regressor = regressor

    def predict(self, obs: np.ndarray) -> np.ndarray:
        pred = self.regressor.predict(np.asarray(obs, dtype=np.float64))
        return np.clip(pred.reshape(len(obs), -1), -1.0, 1.0)

    @staticmethod
    def oracle_targets(bank: EpisodeBank, oracle: OraclePolicy, progress: bool = False) -> np.ndarray:
        """The ``oracle``'s action (n, d) on every episode of ``bank``."""
        out = [oracle.episode_search(bank.scorer(i), bank.items[i].episode, bank.action_map, bank.backend)
               for i in tqdm(range(len(bank)), desc="oracle targets", disable=not progress, leave=False)]
        return np.array(out)

    @classmethod
    def fit(cls, obs: np.ndarray, targets: np.ndarray, *, hidden: tuple[int, ...] = (64, 64),
            seed: int = 0) -> AmortisedPolicy:
        """Fit on observations (n, n_features) and oracle actions (n, d)."""
        return cls(mlp_regressor(hidden, seed).fit(np.asarray(obs, dtype=np.float64), targets))


def mlp_regressor(hidden: tuple[int, ...], seed: int) -> Any:
    """An unfitted MLP regressor on standardised features (early stopping on a 10 % hold-out), as the supervised
    tuners use it."""
    mlp = MLPRegressor(hidden_layer_sizes=hidden, early_stopping=True, max_iter=2000, n_iter_no_change=30,
                       learning_rate_init=1e-3, alpha=1e-4, random_state=seed)
    return make_pipeline(StandardScaler(), mlp)
