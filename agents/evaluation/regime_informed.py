"""Two references for the sequential tuners of ``bboxtune/FilterRetune-v0`` that know the true regimes
(``scripts/compare.py --regime-informed``): the per-window regressor told the schedule (``window_regime_informed``)
and the best action per true regime state, chosen with the truth (``regime_oracle``).

On non-stationary simulated tracks (``scenario="nonstationary"``, :mod:`bboxtune.envs.data.sim_regimes`) the right filter
parameters change with the noise regime (ψ, σ_ξ), the manoeuvre bursts and the occlusion gaps. This tuner is
``window_amortised`` (:mod:`bboxtune.agents.evaluation.window_regressor`: the same candidates, behaviour policy,
ensemble and fit) whose
observation is followed by the true schedule around the coming window — no measurement-only tuner can know more
about the regimes — so its share of the one-shot → per-window gap is what the same learner reaches knowing every
regime boundary and level; the rest of the per-window oracle's lead is out of reach of any tuner that only knows
the regimes. It uses the truth at test (``truth_at_test`` "regimes (truth)") and is a reference, not a tuner.

``regime_oracle`` (:class:`RegimeOracle`) splits the frames after the warm-up into true regime states — noise regime ×
in a manoeuvre × in a gap (:func:`regime_states`) — gives each window the state most of its frames are in, and plays
in every window of a state the action with the lowest squared error, against the truth, summed over that state's
windows: the oracles' grid search (:class:`bboxtune.agents.policies.baselines.GridSearch`, the rule's action a
candidate, then local
refinements), each candidate held over the rest of the track in one run (``env.unwrapped.score_rest``). For the FIR family a
window's estimates do not depend on earlier windows' parameters, so the pooled errors are exactly those of the
windows played; for the Kalman family the state carries over and they are an approximation. It is what a tuner that
knew every regime boundary and tuned each regime with the truth would reach — less than the greedy per-window
oracle, which also fits each window's own noise.

The schedule features (:func:`regime_features`, ``REGIME_FEATURE_NAMES``): for each of ``CHUNKS`` stretches of one
window (the ``CHUNKS − 1`` windows before the coming one, then the coming one: an FIR horizon reaches back into the
past regimes) the frame means of ψ, log σ_ξ, being in a manoeuvre, being in a gap and log(1 + frames since the last
noise switch), and whether the stretch lies in the track (1) or before it (0, its other entries 0); then the track's
log σ_w (the first regime's, px/s²) and log τ (s).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np

from bboxtune.agents.evaluation.retune_eval import DEFAULT_SEARCH, RetuneMethod
from bboxtune.agents.evaluation.window_regressor import WindowRegressorPolicy
from bboxtune.agents.policies.baselines import GridSearch, RulePolicy

if TYPE_CHECKING:  # env.unwrapped's type (gymnasium types it as a plain Env)
    from bboxtune.envs.episodes.episode import Episode
    from bboxtune.envs.retune_env import FilterRetuneEnv

WINDOW_REGIME_INFORMED, REGIME_ORACLE = "window_regime_informed", "regime_oracle"
CHUNKS = 5  # windows of schedule features: the coming one and the 4 before it
PER_CHUNK = ("psi", "log_sigma_xi", "manoeuvre", "gap", "log1p_since_switch", "in_track")
REGIME_FEATURE_NAMES = (*(f"w{k}_{name}" for k in range(1 - CHUNKS, 1) for name in PER_CHUNK), "log_sigma_w", "log_tau")


def check_schedule(scenario: dict[str, Any], where: str) -> None:
    """Refuse an episode without a true regime schedule (anything but non-stationary simulation)."""
    if not {"regimes", "manoeuvres", "gaps"} <= scenario.keys():
        raise ValueError(f"{WINDOW_REGIME_INFORMED}: {where} has no regime schedule; it needs scenario='nonstationary' "
                         "with source 'sim' (bboxtune.envs.data.sim_regimes)")


def regime_features(base: Any) -> np.ndarray:
    """``REGIME_FEATURE_NAMES`` (float32) of the FilterRetune-v0 env ``base`` (unwrapped) at its next window, from the
    episode's true schedule."""
    ep, start, W = base.episode, base.window_start, base.config.window
    schedule, T = ep.scenario, len(ep.y)
    check_schedule(schedule, f"episode {ep.meta.get('noise_seed')}")
    psi, log_xi, since = np.empty(T), np.empty(T), np.empty(T)
    for r in schedule["regimes"]:
        psi[r["start"]:r["end"]], log_xi[r["start"]:r["end"]] = r["psi"], np.log(r["sigma_xi"])
        since[r["start"]:r["end"]] = np.arange(r["end"] - r["start"])
    manoeuvre, gap = np.zeros(T), np.zeros(T)
    for lo, hi in schedule["manoeuvres"]:
        manoeuvre[lo:hi] = 1.0
    for lo, hi in schedule["gaps"]:
        gap[lo:hi] = 1.0
    out = []
    for k in range(1 - CHUNKS, 1):
        lo, hi = max(start + k * W, 0), min(start + (k + 1) * W, T)
        if hi <= lo:
            out += [0.0] * len(PER_CHUNK)
            continue
        part = slice(lo, hi)
        out += [psi[part].mean(), log_xi[part].mean(), manoeuvre[part].mean(), gap[part].mean(),
                np.log1p(since[part].mean()), 1.0]
    out += [np.log(schedule["sigma_w"]), np.log(ep.tau)]
    return np.asarray(out, dtype=np.float32)


class RegimeObservation(gym.ObservationWrapper):
    """A FilterRetune-v0 env whose observation is followed by :func:`regime_features` (for fitting)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        n = cast("tuple[int, ...]", env.observation_space.shape)[0] + len(REGIME_FEATURE_NAMES)  # a Box's shape
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (n,), np.float32)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return np.concatenate([observation, regime_features(self.env.unwrapped)])


class RegimeInformedPolicy(WindowRegressorPolicy):
    """``window_amortised`` asked with the observation followed by the true schedule (a reference: see the module)."""

    truth_at_test = "regimes (truth)"

    def act(self, obs: np.ndarray, env: gym.Env | None = None) -> np.ndarray:
        if env is None:
            raise ValueError(f"{WINDOW_REGIME_INFORMED} reads the true schedule from the env; pass env=")
        return super().act(np.concatenate([obs, regime_features(env.unwrapped)]), env)


def regime_states(schedule: dict[str, Any], n_frames: int) -> np.ndarray:
    """(T,) the true regime state of every frame: 4 × the noise regime's index + 2 × in a manoeuvre + in a gap."""
    check_schedule(schedule, "this episode")
    state = np.zeros(n_frames, dtype=np.int64)
    for k, r in enumerate(schedule["regimes"]):
        state[r["start"]:r["end"]] = 4 * k
    for flag, intervals in ((2, schedule["manoeuvres"]), (1, schedule["gaps"])):
        for lo, hi in intervals:
            state[lo:hi] += flag
    return state


class RegimeOracle(RetuneMethod):
    """The best action per true regime state, searched with the truth (see the module docstring)."""

    name, truth_at_test = REGIME_ORACLE, "y (truth, per regime state)"

    def __init__(self, search: GridSearch = DEFAULT_SEARCH) -> None:
        self.search = search

    def play(self, env: gym.Env, obs: np.ndarray) -> list[dict[str, Any]]:
        base = cast("FilterRetuneEnv", env.unwrapped)
        ep, start, W = cast("Episode", base.episode), base.window_start, base.config.window  # episode: set by reset
        truth = ep.truth[start:]
        states = regime_states(ep.scenario, len(ep.y))[start:]
        bounds = [(lo, min(lo + W, len(states))) for lo in range(0, len(states), W)]
        window_state = np.array([np.bincount(states[lo:hi]).argmax() for lo, hi in bounds])
        cache: dict[bytes, np.ndarray] = {}

        def squared(actions: np.ndarray) -> np.ndarray:
            """(A, T − start) squared error of each action held to the end (0: no truth or no estimate)."""
            key = actions.tobytes()
            if key not in cache:
                est = base.score_rest(actions)["estimates"]
                cache[key] = np.nansum((est - truth) ** 2, axis=-1)
            return cache[key]

        rule = RulePolicy().episode_action(ep, base.action_map, base.config.backend)
        best = {}
        for s in np.unique(window_state):
            frames = np.concatenate([np.arange(lo, hi) for (lo, hi), ws in zip(bounds, window_state, strict=False) if ws == s])

            def reward(a: np.ndarray, f: np.ndarray = frames) -> dict[str, np.ndarray]:
                return {"reward": -squared(a)[:, f].sum(axis=1)}

            best[s] = self.search.search(reward, base.action_map.dim, extra=rule[None])[0]
        return [env.step(best[s])[4] for s in window_state]
