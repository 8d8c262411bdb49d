"""A learned gate over a FilterTune-v0 tuner: leave the track alone unless the tuner's action is predicted to pay.

Behind a strong tracker, smoothing has little to gain. On the held-out trackers' output the per-sequence oracle
gains +0.004 success AUC, and a tuner's small misjudgements cost about as much. So a tuner that always smooths ends
a little below the raw measurements (README, "Held-out trackers' output"). The gated tuner (``<model>_gated`` in
``scripts/compare.py --gate``) plays the model's action only where it predicts that action beats the back end's
trust-the-measurement action (:func:`envs.episodes.actions.trust_measurement_action`: no smoothing) by more than a
margin. Elsewhere it plays the trust action. Both parts are learned where the model was trained, never on the
episodes it is scored on:

1. The gain regressor maps the observation to the reward of the model's action minus the reward of the trust action
   (the env's reward: log RMSE ratio, or success AUC / IoU precision difference). It is a ridge regression on
   standardised features, its penalty chosen by leave-one-out (``RidgeCV``), fitted on train-split episodes with
   their truth.
2. The margin is chosen on val-split episodes: the one with the highest mean reward among 0, the quantiles of the
   predicted gains there (opening the top 10, 25, 50, 75 or 90 % of val episodes) and ±∞. Ties go to the larger
   margin, which leaves more episodes alone. +∞ leaves every episode alone; −∞ is the model itself.

Ridge rather than the MLPs of the other regressors: the gains are of order 1e-4 AUC and noisy. In a prototype fit
(the pretrained ``otb_tracker_kf_cmn``, 1,000 train episodes of its 9 trackers, mean gain over the trust action
+0.0005 AUC), a three-MLP ensemble gave the same val mean for every margin from 0 to 0.001: no prediction fell in
that range, so it had fitted the noise. The ridge fit's predictions spread evenly over that range (in-sample
correlation with the gains 0.50).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np
from sklearn.linear_model import RidgeCV
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from agents.baselines import ObsPolicy
from agents.episodes import EpisodeBank
from agents.evaluate import val_episodes
from agents.runs import make_env
from agents.splits import EpisodeSpec, train_seeds
from envs.episodes.actions import trust_measurement_action

GATED = "_gated"  # name suffix: ppo -> ppo_gated (ppo_s0 -> ppo_gated_s0)
OPEN_SHARES = (0.1, 0.25, 0.5, 0.75, 0.9)  # shares of val episodes a quantile margin opens
RIDGE_ALPHAS = np.logspace(-3, 3, 13)


def gated_name(name: str) -> str:
    """``ppo`` -> ``ppo_gated``, ``ppo_s0`` -> ``ppo_gated_s0`` (the seed suffix stays last, as the groups read it)."""
    head, sep, seed = name.rpartition("_s")
    return f"{head}{GATED}{sep}{seed}" if sep and seed.isdigit() else f"{name}{GATED}"


@dataclass(frozen=True, eq=False)
class GatedPolicy(ObsPolicy):
    """Plays ``inner``'s action where ``gain`` predicts it beats ``fallback`` by more than ``margin`` (reward
    units), and ``fallback`` elsewhere."""

    inner: ObsPolicy
    gain: Any  # fitted regressor: observations (n, F) -> predicted reward gain of inner's action over fallback (n,)
    fallback: np.ndarray  # (d,) the trust-the-measurement action
    margin: float  # reward units; inf: always the fallback, -inf: always inner
    name: str = ""

    def opens(self, obs: np.ndarray) -> np.ndarray:
        """Where ``inner``'s action is played, (n,) bool."""
        return self.gain.predict(np.asarray(obs, dtype=np.float64)) > self.margin

    def predict(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs)
        return np.where(self.opens(obs)[:, None], self.inner.predict(obs), self.fallback[None])


def gain_labels(bank: EpisodeBank, inner: ObsPolicy, fallback: np.ndarray) -> np.ndarray:
    """Per episode of ``bank``, the reward of ``inner``'s action minus that of ``fallback`` (n,)."""
    actions = inner.predict(bank.observations)
    return np.array([float(np.subtract(*bank.score(i, np.stack([a, fallback]))["reward"]))
                     for i, a in enumerate(actions)])


def fit_gain(obs: np.ndarray, gains: np.ndarray) -> Any:
    """Ridge regression (penalty by leave-one-out over ``RIDGE_ALPHAS``) of ``gains`` (n,) on standardised ``obs``
    (n, F); episodes with a non-finite gain are left out (ValueError if fewer than 2 remain)."""
    keep = np.isfinite(gains)
    if keep.sum() < 2:
        raise ValueError(f"{keep.sum()} of {len(gains)} training episodes have a finite gain; the gate needs >= 2")
    return make_pipeline(StandardScaler(), RidgeCV(alphas=RIDGE_ALPHAS)).fit(np.asarray(obs, np.float64)[keep], gains[keep])


def fit_gate(bank: EpisodeBank, inner: ObsPolicy) -> GatedPolicy:
    """``inner`` gated by a gain regressor fitted on ``bank`` (train-split episodes), margin +∞ until chosen."""
    fallback = trust_measurement_action(bank.backend, bank.action_map.tune)
    gain = fit_gain(bank.observations, gain_labels(bank, inner, fallback))
    return GatedPolicy(inner, gain, fallback, np.inf, gated_name(inner.name))


@dataclass(frozen=True)
class MarginChoice:
    """The chosen margin and what each candidate scored on the validation episodes."""

    margin: float
    val_means: dict[float, float]  # margin -> mean reward on val
    val_open: dict[float, float]  # margin -> share of val episodes where the model's action is played


def choose_margin(gated: GatedPolicy, env: gym.Env, episodes: Sequence[EpisodeSpec]) -> MarginChoice:
    """The margin of ``gated`` with the highest mean reward on the validation ``episodes`` of ``env`` (a val-split
    FilterTune-v0 env); candidates and ties as in the module docstring."""
    if not episodes:
        raise ValueError("no validation episodes to choose the gate's margin on")
    base = env.unwrapped
    preds, rewards = [], []
    for spec in episodes:
        obs, _ = env.reset(options=spec.options())
        preds.append(float(gated.gain.predict(np.asarray(obs, np.float64)[None])[0]))
        rewards.append(base.score(np.stack([gated.inner.predict(np.asarray(obs)[None])[0], gated.fallback]))["reward"])
    g, r = np.array(preds), np.array(rewards)  # (n,), (n, 2): model, fallback
    margins = sorted({-np.inf, 0.0, np.inf, *(float(np.quantile(g, 1.0 - q)) for q in OPEN_SHARES)})
    means = {m: float(np.mean(np.where(g > m, r[:, 0], r[:, 1]))) for m in margins}
    share = {m: float(np.mean(g > m)) for m in margins}
    best = max(margins, key=lambda m: (means[m] if np.isfinite(means[m]) else -np.inf, m))
    return MarginChoice(best, means, share)


def with_margin(gated: GatedPolicy, margin: float) -> GatedPolicy:
    """``gated`` with another margin."""
    return replace(gated, margin=float(margin))


def describe_choice(name: str, choice: MarginChoice) -> str:
    """One summary line: the chosen margin and each candidate's val mean and open share."""
    each = ", ".join(f"{m:+.3g}: {choice.val_means[m]:+.5f} ({choice.val_open[m]:.0%} open)" for m in choice.val_means)
    return f"{name} margin {choice.margin:+.3g} (val mean reward per margin: {each})"


def fit_gates(models: Sequence[ObsPolicy], env_id: str, env_kwargs: dict[str, Any], *, train_episodes: int,
              n_val: int, seeds_per_sequence: int = 1, seed: int = 0) -> tuple[list[GatedPolicy], str]:
    """Each of ``models`` gated (:func:`fit_gate`, :func:`choose_margin`) on the env the models were trained on
    (``env_id``, ``env_kwargs``: the run's own, not the evaluation env's): ``train_episodes`` train-split episodes
    drawn with ``seed`` for the gain regressors and :func:`agents.evaluate.val_episodes` (``n_val`` for drawn
    sources, ``seeds_per_sequence`` for "otb") for the margins; and one summary line describing the fits and choices."""
    bank = EpisodeBank(make_env(env_id, env_kwargs, split="train"), train_seeds(np.random.default_rng(seed), train_episodes))
    val_env = make_env(env_id, env_kwargs, split="val")
    episodes = val_episodes(val_env, n_val, seeds_per_sequence)
    gated, lines = [], []
    for model in models:
        unset = fit_gate(bank, model)
        choice = choose_margin(unset, val_env, episodes)
        gated.append(with_margin(unset, choice.margin))
        lines.append(describe_choice(unset.name, choice))
    return gated, (f"the run's own env `{env_kwargs}`: gain regressors fitted on {len(bank)} train-split episodes (seed "
                   f"{seed}), margins chosen on {len(episodes)} val-split episodes; " + "; ".join(lines))
