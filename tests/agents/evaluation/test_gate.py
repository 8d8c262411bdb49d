"""bboxtune.agents.evaluation.gate: the gated tuner uses its model's action only above the margin and leaves the
measurements alone
elsewhere, the gain regressor learns which episodes a fixed smoothing pays on, and the margin is chosen on val
episodes (ties to leaving episodes alone)."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune.agents.episodes import EpisodeBank
from bboxtune.agents.evaluation.evaluate import val_episodes
from bboxtune.agents.evaluation.gate import (
    GatedPolicy,
    choose_margin,
    fit_gain,
    fit_gate,
    gain_labels,
    gated_name,
    pick_margin,
    with_margin,
)
from bboxtune.agents.policies.baselines import ObsPolicy
from bboxtune.agents.policies.gate_file import Gate
from bboxtune.agents.splits import split_seeds, train_seeds
from bboxtune.agents.training.runs import make_env
from bboxtune.envs import TUNE_ID

SHORT = {"track_length": 100}


class Constant(ObsPolicy):
    """The same action for every observation."""

    def __init__(self, action: list[float], name: str = "constant") -> None:
        self.action = np.asarray(action, dtype=np.float64)
        self.name = name

    def predict(self, obs: np.ndarray) -> np.ndarray:
        return np.repeat(self.action[None], len(obs), axis=0)


class FirstFeature:
    """A 'regressor' predicting the first feature."""

    def predict(self, x: np.ndarray) -> np.ndarray:
        return x[:, 0]


@pytest.mark.parametrize(("name", "gated"), [("ppo", "ppo_gated"), ("ppo_s0", "ppo_gated_s0"), ("ppo_best", "ppo_best_gated"),
                                             ("ppo_s12", "ppo_gated_s12"), ("a_sx", "a_sx_gated")])
def test_gated_name_keeps_the_seed_suffix_last(name: str, gated: str) -> None:
    assert gated_name(name) == gated


def test_the_model_acts_only_above_the_margin() -> None:
    gated = GatedPolicy(Constant([0.3, 0.4]), Gate(FirstFeature(), margin=0.5), name="g")
    obs = np.array([[0.2, 9.0], [0.6, 9.0], [0.5, 9.0], [-3.0, 9.0]])
    assert gated.opens(obs).tolist() == [False, True, False, False]
    assert [gated.leaves_alone(o) for o in obs] == [True, False, True, True]
    assert gated.predict(obs).tolist() == [[0.3, 0.4]] * 4 and gated.act(obs[1]).tolist() == [0.3, 0.4]
    assert not any(with_margin(gated, -np.inf).leaves_alone(o) for o in obs)
    assert all(with_margin(gated, np.inf).leaves_alone(o) for o in obs)


def test_the_gain_regressor_leaves_out_non_finite_gains_and_needs_two() -> None:
    obs = np.arange(8.0).reshape(4, 2)
    fit = fit_gain(obs, np.array([0.0, 1.0, np.nan, 3.0]))
    assert np.allclose(fit.predict(obs[[0, 1, 3]]), [0.0, 1.0, 3.0], atol=0.05)
    with pytest.raises(ValueError, match="1 of 3 training episodes have a finite gain"):
        fit_gain(obs[:3], np.array([np.inf, 1.0, np.nan]))


def test_the_margin_maximises_the_val_gain_and_ties_leave_episodes_alone() -> None:
    predicted = np.linspace(-1.0, 1.0, 20)
    choice = pick_margin(predicted, np.where(predicted > 0.4, 1.0, -1.0))  # only the top quarter gains
    assert choice.margin == pytest.approx(np.quantile(predicted, 0.75)) and choice.val_open[choice.margin] == 0.25
    assert choice.val_means[choice.margin] == 0.25 and choice.val_means[np.inf] == 0.0 and choice.val_means[-np.inf] == -0.4
    assert len(choice.val_means) == 8  # -inf, 0, five quantiles, +inf
    nothing = pick_margin(predicted, np.zeros(20))  # every margin ties: leave every episode alone
    assert nothing.margin == np.inf and set(nothing.val_means.values()) == {0.0}
    assert pick_margin(predicted, np.full(20, np.nan)).margin == np.inf  # no usable estimate counts as a loss
    with pytest.raises(ValueError, match="needs >= 1 of each"):
        pick_margin(np.array([]), np.array([]))


def test_a_fitted_gate_opens_where_smoothing_pays() -> None:
    """ufir_cmn with one fixed mid-range action (ψ ≈ 0.5, N ≈ 28): it beats the raw measurements on most simulated
    tracks but not all. The regressor, fitted on 60 train episodes, predicts the gain on 40 val episodes it never
    saw, and the gate at the margin chosen there beats both always smoothing and never smoothing."""
    train_env, val_env = make_env(TUNE_ID, SHORT, split="train"), make_env(TUNE_ID, SHORT, split="val")
    inner = Constant([0.0, 0.0])
    gated = fit_gate(EpisodeBank(train_env, train_seeds(np.random.default_rng(0), 60)), inner)
    assert gated.name == "constant_gated" and gated.gate.margin == np.inf
    val = EpisodeBank(val_env, split_seeds("val", 40))
    gains = gain_labels(val, inner)
    assert 0.1 < np.mean(gains > 0) < 0.95  # both kinds of episode exist
    assert np.corrcoef(gated.gate.gain.predict(val.observations), gains)[0, 1] > 0.8
    choice = choose_margin(gated, val_env, val_episodes(val_env, 40))
    assert np.isfinite(choice.margin) and choice.val_open[np.inf] == 0.0 and choice.val_open[-np.inf] == 1.0
    assert choice.val_means[-np.inf] == pytest.approx(np.mean(gains))  # the same val episodes, scored in the env
    assert choice.val_means[choice.margin] > max(choice.val_means[-np.inf], 0.0) + 0.05
    with pytest.raises(ValueError, match="no validation episodes"):
        choose_margin(gated, val_env, [])
