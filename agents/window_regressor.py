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
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from agents.baselines import GridSearch, ObsPolicy, mlp_regressor

WINDOW_AMORTISED = "window_amortised"


@dataclass(frozen=True)
class WindowRegressorSettings:
    """How the per-window regressor is fitted."""

    candidates: int = 121  # about this many grid actions (GridSearch.points per dimension: d=2 → 11², d=3 → 4³)
    explore: float = 0.5  # probability of a random candidate in a training window (else the window's best)
    hidden: tuple[int, ...] = (64, 64)  # MLP hidden layers (as the RL policy)
    ensemble: int = 3  # MLPs fitted on the same data from different initialisations; their predictions are averaged


def candidate_grid(d: int, n: int) -> np.ndarray:
    """The (A, d) grid of actions in [-1, 1]^d with ``GridSearch(budget=n).points(d)`` values per dimension."""
    axis = np.linspace(-1.0, 1.0, GridSearch(budget=n).points(d))
    return np.array(list(product(axis, repeat=d)))


def window_labels(env: gym.Env, candidates: np.ndarray) -> np.ndarray | None:
    """log RMSE (A,) of every candidate on the env's current window, centred on its mean; None when a score is
    not finite (a window without ground truth)."""
    rmse = env.unwrapped.score(candidates)["rmse"]
    if not np.all(np.isfinite(rmse)) or np.any(rmse <= 0):
        return None
    log_rmse = np.log(rmse)
    return log_rmse - log_rmse.mean()


def collect(env: gym.Env, noise_seeds: np.ndarray, candidates: np.ndarray, explore: float, rng: np.random.Generator,
            progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Observations (n, F) and centred log-RMSE labels (n, A) of every window of the episodes ``noise_seeds`` of
    ``env`` (a FilterRetune-v0 env of the train split), played with the behaviour policy of the module docstring."""
    obs_rows, labels = [], []
    for s in tqdm(noise_seeds, desc=f"{WINDOW_AMORTISED} targets", disable=not progress, leave=False):
        obs, _ = env.reset(options={"noise_seed": int(s)})
        done = False
        while not done:
            y = window_labels(env, candidates)
            if y is not None:
                obs_rows.append(obs)
                labels.append(y)
            explore_now = y is None or rng.random() < explore
            action = candidates[rng.integers(len(candidates))] if explore_now else candidates[np.argmin(y)]
            obs, _, done, _, _ = env.step(action)
    if not labels:
        raise ValueError(f"{WINDOW_AMORTISED}: no window with finite scores in {len(noise_seeds)} training episodes")
    return np.asarray(obs_rows, dtype=np.float64), np.asarray(labels)


class WindowRegressorPolicy(ObsPolicy):
    """Plays the candidate whose predicted (centred) log RMSE on the coming window is lowest."""

    def __init__(self, regressor: Any, candidates: np.ndarray, name: str = WINDOW_AMORTISED) -> None:
        self.regressor = regressor
        self.candidates = candidates
        self.name = name

    def predict(self, obs: np.ndarray) -> np.ndarray:
        scores = self.regressor.predict(np.asarray(obs, dtype=np.float64)).reshape(len(obs), -1)
        return self.candidates[np.argmin(scores, axis=1)]

    @classmethod
    def fit(cls, env: gym.Env, noise_seeds: np.ndarray, *, settings: WindowRegressorSettings = WindowRegressorSettings(),
            seed: int = 0, name: str = WINDOW_AMORTISED, progress: bool = False) -> WindowRegressorPolicy:
        """Fit on the windows of the train-split episodes ``noise_seeds`` of the FilterRetune-v0 env ``env``."""
        if not 0.0 <= settings.explore <= 1.0:
            raise ValueError(f"explore={settings.explore}; allowed: 0 <= explore <= 1")
        if settings.ensemble < 1:
            raise ValueError(f"ensemble={settings.ensemble}; allowed: >= 1")
        candidates = candidate_grid(env.unwrapped.action_map.dim, settings.candidates)
        obs, labels = collect(env, noise_seeds, candidates, settings.explore, np.random.default_rng((seed, 7)), progress)
        members = [mlp_regressor(settings.hidden, seed * settings.ensemble + k).fit(obs, labels)
                   for k in range(settings.ensemble)]
        return cls(MeanRegressor(members), candidates, name=name)


class MeanRegressor:
    """The mean prediction of fitted regressors (an ensemble)."""

    def __init__(self, members: list[Any]) -> None:
        self.members = members

    def predict(self, x: np.ndarray) -> np.ndarray:
        return np.mean([m.predict(x) for m in self.members], axis=0)
