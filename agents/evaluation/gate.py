"""A learned gate over a FilterTune-v0 tuner: leave the track alone unless the tuner's action is predicted to pay.

Behind a strong tracker, smoothing has little to gain. On the held-out trackers' output the per-sequence oracle
gains +0.004 success AUC, and a tuner's small misjudgements cost about as much. So a tuner that always smooths ends
a little below the raw measurements (docs/results-otb.md, "Held-out trackers' output"). The gated tuner (``<model>_gated`` in
``scripts/compare.py --gate``) uses the model's action only where it predicts that the action beats the raw
measurements by more than a margin. Elsewhere it leaves the track alone: its estimate is the measurements
themselves, scored exactly as ``raw`` (``Policy.leaves_alone``). Not a trust-the-measurement action: those follow
the measurements only to round-off (UFIR-CMN at N = 2, ψ = 0: 1e-13 px), or within 0.1 % of the box scale (KF-CMN).
Tracker boxes are integers, so OTB's success and precision thresholds are met with equality on some frames, and
round-off flips those frames. Both parts are learned where the model was trained, never on the episodes it is scored
on:

1. The gain regressor maps the observation to the reward of the model's action minus the reward of the raw
   measurements (the env's reward kind: log RMSE ratio, or success AUC / IoU precision difference). It is a ridge
   regression on standardised features, its penalty chosen by leave-one-out (``RidgeCV``), fitted on train-split
   episodes with their truth.
2. The margin is chosen on val-split episodes: the one with the highest mean gain over raw among 0, the quantiles of
   the predicted gains there (opening the top 10, 25, 50, 75 or 90 % of val episodes) and ±∞. Ties go to the larger
   margin, which leaves more episodes alone. +∞ leaves every episode alone; −∞ is the model itself.

A fitted gate is plain numbers (:mod:`bboxtune.agents.policies.gate_file`): ``compare.py --gate`` writes each to
``gates/<name>.json``,
and ``smooth.py`` / :class:`bboxtune.agents.smoothing.tuner.Tuner` apply one (``--gate FILE``, or ``gate.json`` in
the tuner's folder).

Ridge rather than the MLPs of the other regressors: the gains are of order 1e-4 AUC and noisy. Prototype fits on
train episodes of the pretrained ``otb_tracker_kf_cmn`` (mean gain +0.0005 AUC over KF-CMN's trust-the-measurement
action) showed this. A three-MLP ensemble (300 episodes) gave the same val mean for every margin from 0 to 0.001,
so none of its predictions fell in that range: it had fitted the noise. A ridge fit (1,000 episodes) spread its
predictions across that range (in-sample correlation with the gains 0.50).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from sklearn.linear_model import RidgeCV
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from bboxtune.agents.episodes import EpisodeBank
from bboxtune.agents.evaluation.evaluate import val_episodes
from bboxtune.agents.policies.baselines import ObsPolicy
from bboxtune.agents.policies.gate_file import Gate, LinearGain
from bboxtune.agents.splits import EpisodeSpec, train_seeds
from bboxtune.agents.training.runs import make_env
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.scoring import reward_from, score_estimates

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.tune_env import FilterTuneEnv

GATED = "_gated"  # name suffix: ppo -> ppo_gated (ppo_s0 -> ppo_gated_s0)
OPEN_SHARES = (0.1, 0.25, 0.5, 0.75, 0.9)  # shares of val episodes a quantile margin opens
RIDGE_ALPHAS = np.logspace(-3, 3, 13)


def gated_name(name: str) -> str:
    """``ppo`` -> ``ppo_gated``, ``ppo_s0`` -> ``ppo_gated_s0`` (the seed suffix stays last, as the groups read it)."""
    head, sep, seed = name.rpartition("_s")
    return f"{head}{GATED}{sep}{seed}" if sep and seed.isdigit() else f"{name}{GATED}"


@dataclass(frozen=True, eq=False)
class GatedPolicy(ObsPolicy):
    """``inner``'s action where ``gate`` opens (its predicted gain over the raw measurements, in reward units, above
    its margin); the measurements left alone elsewhere (:meth:`leaves_alone`)."""

    inner: ObsPolicy
    gate: Gate  # margin inf: every episode left alone, -inf: always inner
    name: str = ""

    def opens(self, obs: np.ndarray) -> np.ndarray:
        """Where ``inner``'s action is used, (n,) bool."""
        return self.gate.opens(obs)

    def predict(self, obs: np.ndarray) -> np.ndarray:
        """``inner``'s actions (n, d): what the filter is set to where the gate opens."""
        return self.inner.predict(obs)

    def leaves_alone(self, obs: np.ndarray) -> bool:
        return not bool(self.opens(np.asarray(obs)[None])[0])


def gain_over_raw(scores: dict[str, np.ndarray], ep: Episode, kind: str) -> np.ndarray:
    """The reward of ``kind`` of candidates' ``scores`` (each (A,)) measured against the raw measurements of ``ep``
    instead of the env's reference (A,)."""
    raw = score_estimates(ep.y[None], ep.truth)
    return reward_from(scores, {k: float(v[0]) for k, v in raw.items()}, kind)


def gain_labels(bank: EpisodeBank, inner: ObsPolicy) -> np.ndarray:
    """Per episode of ``bank``, the gain over raw of ``inner``'s action (n,)."""
    actions = inner.predict(bank.observations)
    return np.array([float(gain_over_raw(bank.score(i, a[None]), bank.items[i].episode, bank.reward_kind)[0])
                     for i, a in enumerate(actions)])


def fit_gain(obs: np.ndarray, gains: np.ndarray) -> LinearGain:
    """Ridge regression (penalty by leave-one-out over ``RIDGE_ALPHAS``) of ``gains`` (n,) on standardised ``obs``
    (n, F); episodes with a non-finite gain are left out (ValueError if fewer than 2 remain)."""
    keep = np.isfinite(gains)
    if keep.sum() < 2:
        raise ValueError(f"{keep.sum()} of {len(gains)} training episodes have a finite gain; the gate needs >= 2")
    fit = make_pipeline(StandardScaler(), RidgeCV(alphas=RIDGE_ALPHAS)).fit(np.asarray(obs, np.float64)[keep], gains[keep])
    scaler, ridge = fit.steps[0][1], fit.steps[1][1]
    return LinearGain(mean=scaler.mean_.copy(), scale=scaler.scale_.copy(), coef=np.asarray(ridge.coef_, np.float64).copy(),
                      intercept=float(ridge.intercept_))


def fit_gate(bank: EpisodeBank, inner: ObsPolicy) -> GatedPolicy:
    """``inner`` gated by a gain regressor fitted on ``bank`` (train-split episodes), margin +∞ until chosen."""
    gain = fit_gain(bank.observations, gain_labels(bank, inner))
    return GatedPolicy(inner, Gate(gain, np.inf), gated_name(inner.name))


@dataclass(frozen=True)
class MarginChoice:
    """The chosen margin and what each candidate scored on the validation episodes."""

    margin: float
    val_means: dict[float, float]  # margin -> mean gain over raw on val (0 for +inf)
    val_open: dict[float, float]  # margin -> share of val episodes where the model's action is used


def pick_margin(predicted: np.ndarray, gains: np.ndarray) -> MarginChoice:
    """The margin (module docstring) for val episodes' ``predicted`` gains and true ``gains`` over raw (n,), where a
    non-finite true gain counts as a loss (the model's estimate is not usable there)."""
    if len(predicted) == 0 or len(predicted) != len(gains):
        raise ValueError(f"{len(predicted)} predictions and {len(gains)} gains; the gate's margin needs >= 1 of each, "
                         "as many")
    gains = np.where(np.isfinite(gains), gains, -np.inf)
    margins = sorted({-np.inf, 0.0, np.inf, *(float(np.quantile(predicted, 1.0 - q)) for q in OPEN_SHARES)})
    means = {m: float(np.mean(np.where(predicted > m, gains, 0.0))) for m in margins}
    share = {m: float(np.mean(predicted > m)) for m in margins}
    return MarginChoice(max(margins, key=lambda m: (means[m], m)), means, share)


def choose_margin(gated: GatedPolicy, env: gym.Env, episodes: Sequence[EpisodeSpec]) -> MarginChoice:
    """:func:`pick_margin` on the validation ``episodes`` of ``env`` (a val-split FilterTune-v0 env)."""
    if not episodes:
        raise ValueError("no validation episodes to choose the gate's margin on")
    base = cast("FilterTuneEnv", env.unwrapped)
    predicted, gains = [], []
    for spec in episodes:
        obs = np.asarray(env.reset(options=spec.options())[0])
        predicted.append(float(gated.gate.gain.predict(obs[None])[0]))
        scores = base.score(gated.inner.predict(obs[None]))
        gains.append(float(gain_over_raw(scores, cast(Episode, base.episode), base.config.reward)[0]))  # after reset
    return pick_margin(np.array(predicted), np.array(gains))


def with_margin(gated: GatedPolicy, margin: float) -> GatedPolicy:
    """``gated`` with another margin."""
    return replace(gated, gate=Gate(gated.gate.gain, float(margin)))


def describe_choice(name: str, choice: MarginChoice) -> str:
    """One summary line: the chosen margin and each candidate's val mean gain over raw and open share."""
    each = ", ".join(f"{m:+.3g}: {choice.val_means[m]:+.5f} ({choice.val_open[m]:.0%} open)" for m in choice.val_means)
    return f"{name} margin {choice.margin:+.3g} (val mean gain over raw per margin: {each})"


def fit_gates(models: Sequence[ObsPolicy], env_id: str, env_kwargs: dict[str, Any], *, train_episodes: int,
              n_val: int, seeds_per_sequence: int = 1, seed: int = 0) -> tuple[list[GatedPolicy], str, list[str]]:
    """Each of ``models`` gated (:func:`fit_gate`, :func:`choose_margin`) on the env the models were trained on
    (``env_id``, ``env_kwargs``: the run's own, not the evaluation env's): ``train_episodes`` train-split episodes
    drawn with ``seed`` for the gain regressors and :func:`bboxtune.agents.evaluation.evaluate.val_episodes` (``n_val`` for drawn
    sources, ``seeds_per_sequence`` for "otb") for the margins; what they were fitted on, and per gate a line on its
    choice (:func:`describe_choice`)."""
    bank = EpisodeBank(make_env(env_id, env_kwargs, split="train"), train_seeds(np.random.default_rng(seed), train_episodes))
    val_env = make_env(env_id, env_kwargs, split="val")
    episodes = val_episodes(val_env, n_val, seeds_per_sequence)
    gated, lines = [], []
    for model in models:
        unset = fit_gate(bank, model)
        choice = choose_margin(unset, val_env, episodes)
        gated.append(with_margin(unset, choice.margin))
        lines.append(describe_choice(unset.name, choice))
    fitted_on = (f"the run's own env `{env_kwargs}`: gain regressors fitted on {len(bank)} train-split episodes (seed "
                 f"{seed}), margins chosen on {len(episodes)} val-split episodes")
    return gated, fitted_on, lines
