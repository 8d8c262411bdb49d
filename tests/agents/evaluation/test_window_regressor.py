"""bboxtune.agents.evaluation.window_regressor: the per-window full-information regressor (a learned sequential tuner
without RL)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from bboxtune import envs  # noqa: F401  (registers the ids)
from bboxtune.agents.evaluation.retune_eval import OneShot, Sequential, evaluate_retune
from bboxtune.agents.evaluation.window_regressor import (
    AnchoredWindowPolicy,
    WindowRegressorPolicy,
    WindowRegressorSettings,
    anchor_candidates,
    candidate_grid,
    collect,
    fit_regressor,
    residual_offsets,
    select_margin,
    window_labels,
)
from bboxtune.agents.policies.baselines import RulePolicy
from bboxtune.agents.splits import EpisodeSpec, eval_seeds, train_seeds

RETUNE = "bboxtune/FilterRetune-v0"


def _env(backend: str = "ufir_cmn", split: str = "train") -> gym.Env:
    return gym.make(RETUNE, backend=backend, scenario="nonstationary", track_length=200, window=20, split=split)


@pytest.mark.parametrize(("d", "n", "shape"), [(1, 121, (121, 1)), (2, 121, (121, 2)), (3, 121, (64, 3)), (2, 5, (9, 2))])
def test_candidate_grid_spans_the_action_box(d: int, n: int, shape: tuple[int, int]) -> None:
    grid = candidate_grid(d, n)
    assert grid.shape == shape and grid.min() == -1.0 and grid.max() == 1.0
    assert len(np.unique(grid, axis=0)) == len(grid)


def test_labels_are_the_windows_centred_log_rmse() -> None:
    env = _env()
    env.reset(options={"noise_seed": 5})
    cands = candidate_grid(2, 25)
    y = window_labels(env, cands)
    rmse = env.unwrapped.score(cands)["rmse"]
    assert abs(y.mean()) < 1e-12 and np.argmin(y) == np.argmin(rmse)
    np.testing.assert_allclose(y[1:] - y[0], np.log(rmse[1:] / rmse[0]), rtol=1e-12)


def test_collect_has_one_row_per_window_and_replays_with_the_seed() -> None:
    env, cands = _env(), candidate_grid(2, 9)
    seeds = train_seeds(np.random.default_rng(0), 3)
    obs, y = collect(env, seeds, cands, 0.5, np.random.default_rng(1))
    assert obs.shape == (3 * 9, env.observation_space.shape[0]) and y.shape == (3 * 9, len(cands))  # 200 / 20 − 1 windows
    again = collect(env, seeds, cands, 0.5, np.random.default_rng(1))
    np.testing.assert_array_equal(obs, again[0])
    np.testing.assert_array_equal(y, again[1])


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn"])
def test_fitted_tuner_beats_the_average_candidate_on_held_out_windows(backend: str) -> None:
    """On val-split windows the candidate it picks has a far lower log RMSE than the mean candidate (label 0) and is
    about as good as the best single candidate chosen afterwards with the truth; it plays every window."""
    settings = WindowRegressorSettings(candidates=27, hidden=(32,))
    policy = WindowRegressorPolicy.fit(_env(backend), train_seeds(np.random.default_rng(2), 30), settings=settings, seed=0)
    assert policy.candidates.shape == ((27, 3) if backend == "kf_cmn" else (25, 2))
    env = _env(backend, split="val")
    chosen, labels = [], []
    for s in eval_seeds("val", 6):
        obs, _ = env.reset(options={"noise_seed": int(s)})
        done = False
        while not done:
            action = policy.act(obs, env)
            assert any(np.array_equal(action, c) for c in policy.candidates)
            labels.append(window_labels(env, policy.candidates))
            chosen.append(labels[-1][np.flatnonzero((policy.candidates == action).all(1))[0]])
            obs, _, done, _, _ = env.step(action.astype(np.float32))
    best_fixed = np.mean(labels, axis=0).min()  # the best single candidate for all these windows, chosen with the truth
    assert np.mean(chosen) < -0.3 and np.mean(chosen) < best_fixed + 0.1  # measured: ufir_cmn −1.59 / −1.50, kf_cmn −0.70 / −0.74


@pytest.mark.parametrize(("settings", "message"), [(WindowRegressorSettings(explore=1.5), "explore=1.5"),
                                                   (WindowRegressorSettings(ensemble=0), "ensemble=0"),
                                                   (WindowRegressorSettings(margins=()), "margins=()"),
                                                   (WindowRegressorSettings(margins=(0.1, -1.0)), "margins="),
                                                   (WindowRegressorSettings(margins=(np.nan,)), "margins=")])
def test_bad_settings_are_refused(settings: WindowRegressorSettings, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        WindowRegressorPolicy.fit(_env(), np.array([1]), settings=settings)


class FixedOneShot(OneShot):
    """An anchor: the same action for every track."""

    name = "fixed"

    def __init__(self, action: np.ndarray) -> None:
        self.action = action

    def choose(self, obs: np.ndarray, env: gym.Env) -> np.ndarray:
        return self.action


class ConstantScores:
    """A regressor predicting the same scores for every observation."""

    def __init__(self, scores: np.ndarray) -> None:
        self.scores = scores

    def predict(self, x: np.ndarray) -> np.ndarray:
        return np.tile(self.scores, (len(x), 1))


def test_collect_with_an_anchor_labels_it_as_one_more_candidate() -> None:
    env, cands, anchor = _env(), candidate_grid(2, 9), np.array([0.3, -0.2])
    seeds = train_seeds(np.random.default_rng(0), 2)
    obs, y = collect(env, seeds, cands, 0.5, np.random.default_rng(1), anchor=FixedOneShot(anchor))
    assert y.shape == (2 * 9, len(cands) + 1) and np.allclose(y.mean(axis=1), 0.0)
    env.reset(options={"noise_seed": int(seeds[0])})
    np.testing.assert_allclose(y[0], window_labels(env, np.vstack([cands, anchor])), rtol=1e-12)


def test_anchored_policy_leaves_the_anchor_only_for_a_gain_above_the_margin() -> None:
    env, cands, anchor = _env(), candidate_grid(2, 9), np.array([0.3, -0.2])
    scores = np.zeros(len(cands) + 1)
    scores[4], scores[-1] = -0.25, 0.05  # candidate 4: predicted 0.3 below the anchor
    for margin, expected in ((0.2, cands[4]), (0.3, anchor), (np.inf, anchor)):
        policy = AnchoredWindowPolicy(ConstantScores(scores), cands, FixedOneShot(anchor), margin)
        obs, _ = env.reset(options={"noise_seed": 3})
        policy.begin_episode()
        np.testing.assert_array_equal(policy.act(obs, env), expected)
    amortised = WindowRegressorPolicy(ConstantScores(scores), cands)  # the same regressor, the anchor's output unused
    np.testing.assert_array_equal(amortised.act(obs), cands[4])
    with pytest.raises(ValueError, match="has 9 outputs; an anchored one has 10"):
        AnchoredWindowPolicy(ConstantScores(scores[:-1]), cands, FixedOneShot(anchor), 0.0).act(obs, env)


def test_select_margin_scores_every_margin_and_breaks_ties_towards_the_anchor() -> None:
    """With the anchor predicted best everywhere every margin plays the anchor: equal means, the largest margin chosen,
    and the mean is the anchor's own log-ratio against the rule."""
    env, cands, anchor = _env(split="val"), candidate_grid(2, 9), np.array([0.3, -0.2])
    scores = np.zeros(len(cands) + 1)
    scores[-1] = -1.0
    policy = AnchoredWindowPolicy(ConstantScores(scores), cands, FixedOneShot(anchor), 0.0)
    episodes = [EpisodeSpec(int(s)) for s in eval_seeds("val", 2)]
    margin, means = select_margin(policy, env, episodes, (0.0, 0.1, np.inf))
    assert margin == np.inf and list(means) == [0.0, 0.1, np.inf] and len(set(means.values())) == 1
    held = [r["log_ratio"] for r in evaluate_retune(env, [Sequential(RulePolicy()), FixedOneShot(anchor)], episodes,
                                                    adaptive=None, imm=None).rows if r["method"] == "fixed"]
    assert means[0.0] == pytest.approx(float(np.mean(held))) and np.isfinite(held).all() and len(held) == 2


def test_anchored_fit_beats_its_anchor_on_held_out_windows() -> None:
    """A deliberately poor anchor (the action box's corner): fitted with it, the regressor's predicted gains lead it to
    better candidates, so with margin 0 the log-ratio against the rule on val episodes is above the anchor's own."""
    settings = WindowRegressorSettings(candidates=25, hidden=(32,))
    anchor = FixedOneShot(np.array([1.0, 1.0]))
    regressor, cands = fit_regressor(_env(), train_seeds(np.random.default_rng(2), 30), settings=settings, anchor=anchor)
    env, episodes = _env(split="val"), [EpisodeSpec(int(s)) for s in eval_seeds("val", 6)]
    _, means = select_margin(AnchoredWindowPolicy(regressor, cands, anchor, 0.0), env, episodes, (0.0, np.inf))
    assert means[0.0] > means[np.inf] + 0.5, means  # measured: +0.08 against −1.51


def test_residual_offsets_leave_out_zero_and_stay_in_the_box() -> None:
    offsets = residual_offsets(3, 0.25, 5)
    np.testing.assert_array_equal(residual_offsets(2, 0.25, 3)[6], [0.25, 0.0])
    assert offsets.shape == (5**3 - 1, 3) and np.all(np.any(offsets != 0.0, axis=1))
    assert offsets.min() == -0.25 and offsets.max() == 0.25 and len(np.unique(offsets, axis=0)) == len(offsets)
    moved = anchor_candidates(np.array([0.9, -1.0, 0.0]), offsets)
    assert moved.min() == -1.0 and moved.max() == 1.0 and moved[:, 2].max() == 0.25


class RecordingScores(ConstantScores):
    """ConstantScores that keeps the inputs it was asked about."""

    def predict(self, x: np.ndarray) -> np.ndarray:
        self.seen = x
        return super().predict(x)


def test_residual_collect_and_policy_move_around_the_anchor() -> None:
    """window_residual: the candidates are the anchor moved by the offsets (labels: those and the anchor), the input is
    the observation followed by the anchor's action, and the policy plays anchor + the best offset above the margin."""
    env, anchor = _env(), np.array([0.9, -0.2])
    offsets = residual_offsets(2, 0.25, 3)
    seeds = train_seeds(np.random.default_rng(0), 2)
    obs, y = collect(env, seeds, offsets, 0.5, np.random.default_rng(1), anchor=FixedOneShot(anchor),
                     around_anchor=True)
    width = env.observation_space.shape[0]
    assert y.shape == (2 * 9, len(offsets) + 1) and obs.shape == (2 * 9, width + 2)
    np.testing.assert_array_equal(obs[:, width:], np.tile(anchor, (len(obs), 1)))
    first, _ = env.reset(options={"noise_seed": int(seeds[0])})
    np.testing.assert_array_equal(obs[0, :width], first)
    np.testing.assert_allclose(y[0], window_labels(env, np.vstack([np.clip(anchor + offsets, -1, 1), anchor])), rtol=1e-12)
    scores = np.zeros(len(offsets) + 1)
    scores[6], scores[-1] = -0.25, 0.05  # offset 6 (+0.25, 0): predicted 0.3 below the anchor
    for margin, expected in ((0.2, [1.0, -0.2]), (0.3, anchor)):  # 0.9 + 0.25 clipped to the box
        regressor = RecordingScores(scores)
        policy = AnchoredWindowPolicy(regressor, offsets, FixedOneShot(anchor), margin, around_anchor=True)
        policy.begin_episode()
        np.testing.assert_allclose(policy.act(first, env), expected)
        np.testing.assert_array_equal(regressor.seen, np.concatenate([first, anchor])[None])
        assert policy.with_anchor(FixedOneShot(anchor), 0.0).around_anchor


@pytest.mark.parametrize(("settings", "anchor", "message"), [
    (WindowRegressorSettings(), None, "offsets are from an anchor"),
    (WindowRegressorSettings(residual_step=0.0), np.zeros(2), "residual_step=0.0; allowed: 0 < residual_step <= 2"),
    (WindowRegressorSettings(residual_step=float("nan")), np.zeros(2), "residual_step=nan"),
    (WindowRegressorSettings(residual_points=1), np.zeros(2), "residual_points=1; allowed: >= 2"),
])
def test_residual_fit_refuses_bad_settings(settings: WindowRegressorSettings, anchor: np.ndarray | None,
                                           message: str) -> None:
    with pytest.raises(ValueError, match=message):
        fit_regressor(_env(), np.array([1]), settings=settings, residual=True,
                      anchor=None if anchor is None else FixedOneShot(anchor))


def test_residual_fit_moves_a_poor_anchor_towards_better_actions() -> None:
    """From the action box's corner, offsets of up to 0.5 reach better actions, and the fitted residual regressor finds
    them: with margin 0 the log-ratio against the rule on val episodes is above the anchor's own."""
    settings = WindowRegressorSettings(hidden=(32,), residual_step=0.5, residual_points=3)
    anchor = FixedOneShot(np.array([1.0, 1.0]))
    regressor, offsets = fit_regressor(_env(), train_seeds(np.random.default_rng(2), 30), settings=settings,
                                       anchor=anchor, residual=True)
    env, episodes = _env(split="val"), [EpisodeSpec(int(s)) for s in eval_seeds("val", 6)]
    policy = AnchoredWindowPolicy(regressor, offsets, anchor, 0.0, around_anchor=True)
    _, means = select_margin(policy, env, episodes, (0.0, np.inf))
    assert means[0.0] > means[np.inf] + 0.2, means
