"""A learned sequential tuner for ``bboxtune/FilterRetune-v0`` without RL: the amortised per-window oracle.

In every window of a training episode the env scores a fixed grid of candidate actions on that window
(``env.unwrapped.score``: full information, every candidate's result, not only the one played), so the fitting
data are (observation, the window's log RMSE of every candidate). A multi-output regressor (an MLP with the RL
policy's hidden layers, on standardised features) learns E[log RMSE(a) − mean_a' log RMSE(a') | observation], and
the tuner plays the candidate with the lowest prediction: a greedy, causal (measurement-only) policy. An argmin
over noisy predictions is itself noisy, so the prediction is the mean of ``ensemble`` MLPs fitted from different
initialisations (measured, ufir_cmn, non-stationary sim, W = 10, the same 19,600 windows: one MLP +0.363 against
the rule on 200 test episodes, three +0.411). Deciding greedily loses nothing for the FIR family, whose carry (the
measurement history) does not depend on the parameters played, so a window's choice does not change later
windows' estimates; for the Kalman family, whose state does, it is an approximation.

Subtracting the candidates' mean in each window does not change which candidate minimises the expectation; it
removes the window's overall error level (a gap, a manoeuvre), which no candidate controls. Log RMSE rather than
squared error: a few candidates diverge in some windows (e.g. ψ near 1 with a short horizon), and squared-error
targets then reach 10⁸ × the median and swamp the fit (measured, ufir_cmn, log-ratio against the rule on 200 test
episodes: non-stationary, W = 50, −0.86 with squared-error targets and +0.23 with log RMSE; stationary, W = 10,
−2.54 and −0.05 with squared errors capped at 10× and 5× the window's median, +0.17 with log RMSE, all three with
the track-so-far features added to the input).

Training episodes are played with a behaviour policy that, per window, takes a uniformly random candidate with
probability ``explore`` and the window's best candidate (known from the labels) otherwise, so the observed
"current action" and residual features cover both tuned and untuned filters. Windows whose scores are not all
finite (no ground truth in the window) are left out.

``window_anchored`` (:class:`AnchoredWindowPolicy`) starts from a one-shot tuner's action for the track (the
anchor: a FilterTune-v0 model's, ``bboxtune.agents.evaluation.retune_eval.OneShotLearned``) and leaves it in a window
only where the
regressor predicts a candidate's log RMSE below the anchor's by more than a margin. For it the anchor is one more
candidate in every training window (its log RMSE a further output), and the margin is chosen on validation
episodes (:func:`select_margin`, ties to the larger margin); an infinite margin is the one-shot tuner itself. An
argmin over 121 noisy predictions is biased low (the winner's curse), so switching on any predicted gain loses where
the anchor is already right (measured, prototype, ufir_cmn, W = 10, offline view, 200 train / 200 test stationary
episodes: margin 0 −0.022 [−0.041, −0.008] against the one-shot tuner, 0.3 −0.011 [−0.027, +0.001]).

``window_residual`` (the same class with ``around_anchor``) re-tunes *around* the anchor: its candidates in an episode are
the anchor plus a small grid of offsets (``residual_step``, ``residual_points`` per dimension, clipped to the action
box), its regressor sees the anchor beside the observation, and it leaves the anchor for the offset with the largest
predicted gain above a margin chosen the same way. A fixed grid is coarse where the action has three dimensions (kf_cmn:
4³ points), so every grid candidate can be far from a good action for the track; offsets keep the one-shot tuner's
choice and adjust it per window (measured, prototype, kf_cmn, W = 10, offline view, 200 train / 100 val / 200 test
non-stationary episodes: the fixed grid anchored, margin chosen on val: ∞, i.e. no switch; offsets of ±0.25, margin
0.2 chosen on val: +0.025 [+0.014, +0.038] against the one-shot tuner; offsets of ±0.5: +0.010 [−0.008, +0.031]).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import product
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from bboxtune.agents.evaluation.retune_eval import OneShot, Sequential, evaluate_retune
from bboxtune.agents.policies.baselines import GridSearch, ObsPolicy, Policy, RulePolicy, mlp_regressor
from bboxtune.agents.splits import EpisodeSpec

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.retune_env import FilterRetuneEnv

WINDOW_AMORTISED, WINDOW_ANCHORED, WINDOW_RESIDUAL = "window_amortised", "window_anchored", "window_residual"


@dataclass(frozen=True)
class WindowRegressorSettings:
    """How the per-window regressor is fitted."""

    candidates: int = 121  # about this many grid actions (GridSearch.points per dimension: d=2 → 11², d=3 → 4³)
    explore: float = 0.5  # probability of a random candidate in a training window (else the window's best)
    hidden: tuple[int, ...] = (64, 64)  # MLP hidden layers (as the RL policy)
    ensemble: int = 3  # MLPs fitted on the same data from different initialisations; their predictions are averaged
    margins: tuple[float, ...] = (0.0, 0.05, 0.1, 0.2, 0.3, np.inf)  # window_anchored: the predicted log-RMSE gains a
    # switch away from the anchor must exceed, one chosen on validation episodes (inf: never switch)
    residual_step: float = 0.25  # window_residual: the largest offset from the anchor per action dimension (action units)
    residual_points: int = 5  # window_residual: offsets per dimension, evenly spaced in [-step, step] (0: the anchor)


def candidate_grid(d: int, n: int) -> np.ndarray:
    """The (A, d) grid of actions in [-1, 1]^d with ``GridSearch(budget=n).points(d)`` values per dimension."""
    axis = np.linspace(-1.0, 1.0, GridSearch(budget=n).points(d))
    return np.array(list(product(axis, repeat=d)))


def residual_offsets(d: int, step: float, points: int) -> np.ndarray:
    """The (K, d) non-zero offsets of the grid with ``points`` values per dimension in [−step, step]."""
    axis = np.linspace(-step, step, points)
    grid = np.array(list(product(axis, repeat=d)))
    return grid[np.any(grid != 0.0, axis=1)]


def anchor_candidates(anchor_action: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The anchor's action moved by each offset, within the action box [−1, 1]^d (K, d)."""
    return np.clip(anchor_action + offsets, -1.0, 1.0)


def window_labels(env: gym.Env, candidates: np.ndarray) -> np.ndarray | None:
    """log RMSE (A,) of every candidate on the env's current window, centred on its mean; None when a score is
    not finite (a window without ground truth)."""
    rmse = cast("FilterRetuneEnv", env.unwrapped).score(candidates)["rmse"]
    if not np.all(np.isfinite(rmse)) or np.any(rmse <= 0):
        return None
    log_rmse = np.log(rmse)
    return log_rmse - log_rmse.mean()


def collect(env: gym.Env, noise_seeds: np.ndarray, candidates: np.ndarray, explore: float, rng: np.random.Generator,
            progress: bool = False, anchor: OneShot | None = None, around_anchor: bool = False
            ) -> tuple[np.ndarray, np.ndarray]:
    """Observations (n, F) and centred log-RMSE labels (n, A) of every window of the episodes ``noise_seeds`` of
    ``env`` (a FilterRetune-v0 env of the train split), played with the behaviour policy of the module docstring.
    With ``anchor`` (a one-shot tuner of the train split) its action for the episode is candidate A + 1 (labels
    (n, A + 1)); with ``around_anchor`` too, ``candidates`` are offsets, the candidates are the anchor's action moved
    by them, and each observation is followed by that action (n, F + d)."""
    obs_rows, labels = [], []
    for s in tqdm(noise_seeds, desc=f"{WINDOW_RESIDUAL if around_anchor else WINDOW_AMORTISED} targets",
                  disable=not progress, leave=False):
        obs, _ = env.reset(options={"noise_seed": int(s)})
        anchor_action = None if anchor is None else np.asarray(anchor.choose(obs, env), dtype=np.float64)
        actions = candidates if anchor_action is None else np.vstack(
            [anchor_candidates(anchor_action, candidates) if around_anchor else candidates, anchor_action])
        done = False
        while not done:
            y = window_labels(env, actions)
            if y is not None:
                obs_rows.append(np.concatenate([obs, anchor_action]) if around_anchor else obs)
                labels.append(y)
            explore_now = y is None or rng.random() < explore
            action = actions[rng.integers(len(actions))] if explore_now else actions[np.argmin(cast(np.ndarray, y))]
            obs, _, done, _, _ = env.step(action)
    if not labels:
        raise ValueError(f"{WINDOW_AMORTISED}: no window with finite scores in {len(noise_seeds)} training episodes")
    return np.asarray(obs_rows, dtype=np.float64), np.asarray(labels)


def fit_regressor(env: gym.Env, noise_seeds: np.ndarray, *, settings: WindowRegressorSettings = WindowRegressorSettings(),
                  seed: int = 0, anchor: OneShot | None = None, residual: bool = False, progress: bool = False
                  ) -> tuple[MeanRegressor, np.ndarray]:
    """The per-window regressor fitted on the windows of the train-split episodes ``noise_seeds`` of the
    FilterRetune-v0 env ``env`` (with ``anchor``: one more output, the anchor's), and its candidates (A, d); with
    ``residual`` (needs ``anchor``), the regressor of ``window_residual`` and its offsets from the anchor (K, d)."""
    if not 0.0 <= settings.explore <= 1.0:
        raise ValueError(f"explore={settings.explore}; allowed: 0 <= explore <= 1")
    if settings.ensemble < 1:
        raise ValueError(f"ensemble={settings.ensemble}; allowed: >= 1")
    if not settings.margins or any(np.isnan(m) or m < 0 for m in settings.margins):
        raise ValueError(f"margins={settings.margins}; allowed: one or more numbers >= 0 (inf: never switch)")
    if residual and anchor is None:
        raise ValueError(f"{WINDOW_RESIDUAL}: the offsets are from an anchor; pass anchor=")
    if not (np.isfinite(settings.residual_step) and 0.0 < settings.residual_step <= 2.0):
        raise ValueError(f"residual_step={settings.residual_step}; allowed: 0 < residual_step <= 2 (action units)")
    if settings.residual_points < 2:
        raise ValueError(f"residual_points={settings.residual_points}; allowed: >= 2")
    d = cast("FilterRetuneEnv", env.unwrapped).action_map.dim
    candidates = (residual_offsets(d, settings.residual_step, settings.residual_points) if residual
                  else candidate_grid(d, settings.candidates))
    obs, labels = collect(env, noise_seeds, candidates, settings.explore, np.random.default_rng((seed, 7)), progress,
                          anchor, around_anchor=residual)
    members = [mlp_regressor(settings.hidden, seed * settings.ensemble + k).fit(obs, labels)
               for k in range(settings.ensemble)]
    return MeanRegressor(members), candidates


class WindowRegressorPolicy(ObsPolicy):
    """Plays the candidate whose predicted (centred) log RMSE on the coming window is lowest (of the regressor's
    first A outputs: a regressor fitted with an anchor has one more)."""

    def __init__(self, regressor: Any, candidates: np.ndarray, name: str = WINDOW_AMORTISED) -> None:
        self.regressor = regressor
        self.candidates = candidates
        self.name = name

    def predict(self, obs: np.ndarray) -> np.ndarray:
        scores = self.regressor.predict(np.asarray(obs, dtype=np.float64)).reshape(len(obs), -1)
        return self.candidates[np.argmin(scores[:, :len(self.candidates)], axis=1)]

    @classmethod
    def fit(cls, env: gym.Env, noise_seeds: np.ndarray, *, settings: WindowRegressorSettings = WindowRegressorSettings(),
            seed: int = 0, name: str = WINDOW_AMORTISED, progress: bool = False) -> WindowRegressorPolicy:
        """Fit on the windows of the train-split episodes ``noise_seeds`` of the FilterRetune-v0 env ``env``."""
        return cls(*fit_regressor(env, noise_seeds, settings=settings, seed=seed, progress=progress), name=name)


class AnchoredWindowPolicy(Policy):
    """Plays the anchor's action (a one-shot tuner's, asked once per episode) and, in a window, the candidate with
    the lowest predicted log RMSE instead where that is below the anchor's prediction by more than ``margin``. With
    ``around_anchor`` (``window_residual``) ``candidates`` are offsets, the candidates are the anchor's action moved by
    them and the regressor's input is the observation followed by that action; else they are fixed actions."""

    def __init__(self, regressor: Any, candidates: np.ndarray, anchor: OneShot, margin: float,
                 name: str = WINDOW_ANCHORED, around_anchor: bool = False) -> None:
        self.regressor = regressor
        self.candidates = candidates
        self.anchor = anchor
        self.margin = margin
        self.name = name
        self.around_anchor = around_anchor
        self._anchor_action: np.ndarray | None = None

    def begin_episode(self) -> None:
        self._anchor_action = None

    def act(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        if self._anchor_action is None:
            self._anchor_action = np.asarray(self.anchor.choose(obs, env), dtype=np.float64)
        x = np.asarray(obs, dtype=np.float64)
        x = np.concatenate([x, self._anchor_action]) if self.around_anchor else x
        scores = self.regressor.predict(x[None]).reshape(-1)
        if len(scores) != len(self.candidates) + 1:
            raise ValueError(f"{self.name}: the regressor has {len(scores)} outputs; an anchored one has "
                             f"{len(self.candidates) + 1} (the candidates' and the anchor's)")
        gain = scores[-1] - scores[:-1]  # predicted log RMSE of the anchor minus each candidate's
        best = int(np.argmax(gain))
        if gain[best] <= self.margin:
            return self._anchor_action
        return anchor_candidates(self._anchor_action, self.candidates[best]) if self.around_anchor else self.candidates[best]

    def with_anchor(self, anchor: OneShot, margin: float | None = None) -> AnchoredWindowPolicy:
        """The same regressor with another anchor (e.g. the same model on another split's env) and margin."""
        return AnchoredWindowPolicy(self.regressor, self.candidates, anchor, self.margin if margin is None else margin,
                                    name=self.name, around_anchor=self.around_anchor)


def select_margin(policy: AnchoredWindowPolicy, env: gym.Env, episodes: Sequence[EpisodeSpec],
                  margins: Sequence[float]) -> tuple[float, dict[float, float]]:
    """The margin of ``margins`` with the highest mean log-ratio against the rule of ``policy`` (its anchor of
    ``env``'s split) on the validation ``episodes`` of ``env``, scored as
    ``bboxtune.agents.evaluation.retune_eval.evaluate_retune`` scores
    a test (ties: the larger margin), and every margin's mean."""
    methods = [Sequential(RulePolicy()), *(Sequential(policy.with_anchor(policy.anchor, m), name=f"margin {m:g}")
                                           for m in margins)]
    rows = evaluate_retune(env, methods, episodes, adaptive=None, imm=None).rows
    means = {float(m): float(np.mean([r["log_ratio"] for r in rows if r["method"] == f"margin {m:g}"])) for m in margins}
    best = max(means, key=lambda m: (means[m] if np.isfinite(means[m]) else -np.inf, m))
    return best, means


class MeanRegressor:
    """The mean prediction of fitted regressors (an ensemble)."""

    def __init__(self, members: list[Any]) -> None:
        self.members = members

    def predict(self, x: np.ndarray) -> np.ndarray:
        return np.mean([m.predict(x) for m in self.members], axis=0)
