"""``bboxtune/FilterRetune-v0``: re-tune the filter every W frames while it runs over the track."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from bboxtune import filters
from bboxtune.envs.episodes.actions import ACCEPTS
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.features import FEATURE_NAMES, WINDOW_FEATURE_NAMES, measurement_features, window_features
from bboxtune.envs.episodes.scoring import (
    SCORE_KEYS,
    box_model,
    check_candidates,
    detections,
    hold_missing,
    reward_from,
    run_positions,
    score_estimates,
)
from bboxtune.envs.track_env import TrackEnv, check_reset_args


class FilterRetuneEnv(TrackEnv):
    """
    ## Description
    The track of :class:`bboxtune.envs.tune_env.FilterTuneEnv` is cut into windows of ``window`` = W frames
    (default 50). The first window is filtered with the fixed rule (a warm-up the agent observes); then
    each step sets the filter's parameters for the next window, the filter runs over it and the reward
    compares the window's estimates with the fixed rule's. The filter's memory carries over across windows:

    * Kalman family (kf, kf_cmn, ukf, bytetrack_kf): the posterior state and covariance at the window's last
      frame (and, for kf_cmn, the last measurement, needed for the differenced measurement) start the next
      window, whose new σ/ψ (or weights) apply from its first frame on (:meth:`bboxtune.filters.base.Filter.run_from`).
    * FIR family: the measurement buffer is the whole past, so a horizon change takes effect at once: the
      first estimate of the window already averages over the last N_new measurements (reaching back into
      earlier windows); nothing is re-initialised, and only while the track is shorter than N_new does the
      usual start-up rule (growing horizon) apply.

    A frame where the filter has no estimate although it had one before (an FIR horizon holding too few
    measurements to determine the state, inside an occlusion gap longer than the horizon) shows the last
    estimate, held (``bboxtune.envs.episodes.scoring.hold_missing``), for every candidate and the rule alike, so every
    candidate is scored on the same frames. (Before, such frames were left out of that candidate's RMSE: a short
    horizon through a gap skipped the frames where errors are largest. Measured on 100 non-stationary test
    episodes, W = 10: a per-window regressor left 0.6 such frames per episode unscored, 2.0 when it could see
    the coming window, the rule and the one-shot tuner none.)

    ## Action Space
    As FilterTune-v0: ``Box(-1, 1, (d,), float32)`` mapped by ``bboxtune.envs.episodes.actions.ActionMap``; ``step`` takes
    exactly one action of shape (d,), finite, within [-1, 1] (1e-6 float32 tolerance, clipped); anything
    else raises ``ValueError`` (``TypeError`` for a non-numeric dtype) and leaves the episode where it was.

    ## Observation Space
    ``Box(-inf, inf, (20 + 4 + d + 1,), float32)`` (``retune_view="causal"``, default) or
    ``Box(-inf, inf, (20 + 4 + d + 1 + 40,), float32)`` (``retune_view="offline"``), measurement-only (never the
    truth or the true regimes):

    | index        | what                                                                                 | unit |
    |--------------|--------------------------------------------------------------------------------------|------|
    | 0–19         | ``bboxtune.envs.episodes.features.FEATURE_NAMES`` on the last ``history`` frames      | see there |
    |              | before the window (default 100; the fixed rule's estimates on them are the pilot      |      |
    |              | residual)                                                                             |      |
    | 20–23        | ``bboxtune.envs.episodes.features.WINDOW_FEATURE_NAMES``: the filter's residuals      | –    |
    |              | y − ŷ in the window just filtered (log variance / scale², lag-1 autocorrelation, log  |      |
    |              | variance minus the rule's, share of missing frames) — how the current parameters are |      |
    |              | doing                                                                                 |      |
    | 24 … 23 + d  | the current action (the rule's after the warm-up)                                     | [-1, 1] |
    | 24 + d       | the fraction of the track already filtered                                            | 0..1 |
    | 25 + d … 44 + d | ``"offline"`` only: ``FEATURE_NAMES`` on the **coming** window's measurements (the frames | see there |
    |              | the step's action will filter; pilot residual: the rule's estimates on them); zeros in |      |
    |              | the terminal observation, which has no window left                                    |      |
    | 45 + d … 64 + d | ``"offline"`` only: ``FEATURE_NAMES`` on the **whole** track (exactly FilterTune-v0's   | see there |
    |              | observation of the episode: what a one-shot tuner sees)                               |      |

    ``env.unwrapped.observation_names`` names every entry (:func:`retune_observation_names`: the feature names,
    ``action_<parameter>``, ``progress``, ``coming_<feature>``, ``track_<feature>``).

    ``"causal"`` is what a filter behind a live tracker can know when it re-tunes: the frames already filtered.
    ``"offline"`` is for smoothing a recorded track (a tracker's saved results), where every measurement exists
    before the filter runs: the filter itself stays causal, but the tuner may look ahead at the measurements (a
    gap, a manoeuvre, a drifting stretch to come) — the information of the offline one-shot tuner
    (``oneshot_learned`` in ``bboxtune.agents.retune_eval``), plus where in the track it is.

    ## Rewards
    The env's reward (as FilterTune-v0: ``rmse`` → log(RMSE_rule / RMSE), others action minus rule, against
    the rule run alongside on the same track) of the **track so far**, scored from the end of the warm-up
    window: a step's reward is how much that changed with the step's window (``retune_reward="track"``,
    default), so the undiscounted return of an episode is exactly the whole track's reward — the metric the
    evaluation reports — and a window weighs as much as its errors do (an occlusion gap or a manoeuvre, where
    RMSE is made, counts more than a quiet stretch). ``retune_reward="window"``: each window's own reward
    instead (0 when it has no ground truth), whose sum is not the track's (measured, seed 0, 200 nonstationary
    test episodes: a PPO tuner trained on it reached +0.17 track log-ratio against the rule, a one-shot tuner
    +0.41 — it optimised the mean of window ratios, not the track's RMSE). The filter state carries over, so an
    action also shapes later windows' rewards — train with discounting across windows
    (``agents/hyperparams/ppo.yml``: γ = 0.95, λ = 0.9). ``score_rest(actions)`` scores actions held to the
    track's end (one-shot tuning from here on), ``score(actions)`` the current window only (both refuse a batch
    whose scoring would not fit in the available memory, ``bboxtune.envs.data.memory``); ``estimates`` are
    the boxes filtered so far, ``rule_estimates`` the rule's, ``window_start`` the next window's first frame, and
    ``features_so_far()`` the FilterTune-v0 observation of the frames filtered so far (what a one-shot tuner would
    see if the track ended there).

    ## Starting State
    As FilterTune-v0: ``reset(options={"sequence": ..., "noise_seed": ..., "tracker": ...})`` pins an episode (the
    tracker drawn per episode from ``trackers``, a ``mix`` part — sim, otb, otb_tracker or mot — per noise seed),
    arguments and options are checked the same way, a rejected reset changes nothing, and reset's ``info`` is
    ``{"track": {...}}`` without the true scenario. The first window is already filtered by the rule.

    Every episode has at least 2 windows (2·W frames: the warm-up and one step). ``sim`` and ``video``
    tracks have ``track_length`` frames, so ``track_length < 2 * window`` raises ``ValueError`` at
    construction. OTB sequences shorter than 2·W are left out of the episode pool (with W = 50: Bird2 in
    train, Deer, Football1, Skiing, KiteSurf in test): an unpinned reset re-draws the sequence from the
    noise seed's own generator (seeds whose first pick is long enough keep it), and pinning a short one
    raises ``ValueError`` naming its length.

    ## Episode End
    ``terminated=True`` after the track's last window (ceil(T / W) − 1 steps); ``truncated`` is never set.
    ``info`` holds the window's ``rmse``, ``rule_rmse``, ``success_auc``, ``rule_success_auc`` (and the other
    scores, with ``rule_`` twins), ``n_frames`` (of the window), ``params``, ``rule_params``, ``window``
    (start, end) and ``track`` (as at reset); the last step adds ``track_rmse`` and ``track_rule_rmse``
    over the whole track and ``scenario``, the true scenario (as in FilterTune-v0; with
    ``scenario="nonstationary"`` also the switch times and regimes, manoeuvres and gaps,
    :mod:`bboxtune.envs.data.sim_regimes`). The truth comes only with the last step because every step is a decision about
    the same track: revealing it earlier would hand it to the later decisions.

    ## Arguments
    Those of FilterTune-v0 (``bboxtune.envs.episodes.config.EnvConfig``, checked the same way; ``trackers``, ``mix_weights``
    (the triple or the 4-tuple with the mot part), ``mot_root`` and ``source="mix"`` included: every part of a mix
    draws episodes of at least two windows — the OTB and mot parts leave shorter sequences / identities out of
    their pools — and the sim part's ``track_length`` must allow that); ``window``, ``history``, ``retune_reward``
    and ``retune_view`` are used here.
    ``scenario="nonstationary"`` gives simulated tracks whose right parameters change within the track
    (regime switches of ψ and σ_ξ, manoeuvre bursts, occlusion gaps: :mod:`bboxtune.envs.data.sim_regimes`), where
    re-tuning has something to gain. ``detection_dropout``, ``miss_rate_range``, ``miss_run_range`` and
    ``outlier_rate_range`` add a real detection stream's missed frames and wrong boxes to the episodes as in
    FilterTune-v0 (a window may then hold few or no measurements; the drawn rates come with the last step's
    ``info["scenario"]``).

    >>> import gymnasium as gym, envs
    >>> env = gym.make("bboxtune/FilterRetune-v0", backend="kf_cmn", track_length=200, window=50)
    >>> obs, info = env.reset(seed=1)
    >>> obs.shape
    (28,)
    >>> steps = 0
    >>> while True:
    ...     obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    ...     steps += 1
    ...     if terminated:
    ...         break
    >>> steps, info["window"], sorted(info["scenario"])
    (3, (150, 200), ['psi', 'sigma_w', 'sigma_xi'])

    ## Version History
    * v0: initial version.
    * v0, hardened (as FilterTune-v0): truth only in the last step's ``info["scenario"]``; checked
      arguments, options and actions; OTB sequences shorter than 2 windows left out of the pool (before,
      drawing one crashed the episode); ``track_length < 2 * window`` refused at construction.
    * v0, tracker sets and mix (as FilterTune-v0; earlier arguments' episodes unchanged bit for bit):
      ``trackers``, the ``tracker`` reset option, ``source="mix"``.
    * v0, sequential tuning: the observation adds the 4 window-residual features (shape 20 + d + 1 →
      20 + 4 + d + 1; no model had been trained on the old one, and loading refuses a model of another
      shape); the reward is the change of the track-so-far reward (``retune_reward="track"``; the old
      per-window reward is ``retune_reward="window"``); ``scenario="nonstationary"``; ``score_rest`` and
      ``estimates``.
    * v0, held estimates: a frame without an estimate after the filter's first is scored as the last estimate
      held (see Description); episodes without such frames score as before.
    * v0, offline view: ``retune_view="offline"`` adds the coming window's and the whole track's measurement
      features (shape + 40); the default ``"causal"`` observation is unchanged.
    * v0, detection errors (as FilterTune-v0; defaults off, no change to any episode).
    * v0, MOT15 in the mix (as FilterTune-v0; earlier arguments' episodes unchanged bit for bit): ``mix_weights``
      (sim, otb, otb_tracker, mot), ``mot_root`` with a positive mot weight; the sim part's ``sim_noise`` /
      ``scenario`` with OTB weight.
    * v0, ``mot_holdout`` (as FilterTune-v0; default None: no change to any episode).
    """

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        config = EnvConfig.from_kwargs(**kwargs)
        if config.reward_baseline != "rule":
            raise ValueError(f"reward_baseline={config.reward_baseline!r} with FilterRetune-v0; allowed: 'rule' "
                             "(a window's reward is measured against the rule; 'raw' is a FilterTune-v0 option)")
        if config.features != "base":
            raise ValueError(f"features={config.features!r} with FilterRetune-v0; allowed: 'base' (the feature set "
                             "'msd' is a FilterTune-v0 option)")
        n_obs = len(retune_observation_names(config))  # the Observation Space table's entries
        super().__init__(n_obs - len(FEATURE_NAMES), render_mode=render_mode, **kwargs)
        W = self.config.window
        self.source.require_frames(2 * W, f"FilterRetune-v0 with window={W} (a warm-up window and one step)")

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        seed, options = check_reset_args(seed, options)
        with self._seeded(seed):
            ep = self._draw(options)  # the source draws only episodes of at least 2 windows
        self.episode = ep
        self._rule_params = self.rule_params(ep)
        self._rule_est = hold_missing(run_positions(self.config.backend, ep.y, ep.tau, self._rule_params))[0]
        offline = self.config.retune_view == "offline"
        self._track_features = self._features(0, len(ep.y)) if offline else None  # the same for every step
        self._action = self.action_map.to_actions(self._rule_params, ep.nominal)[0].astype(np.float32)
        self._estimate = np.full_like(ep.y, np.nan)
        self._carry = None
        self._start = 0
        self._track_reward = 0.0  # the reward of the track so far (frames after the warm-up), "track" rewards
        self._advance(self._rule_params)  # warm-up window, filtered by the rule
        return self._observe(), {"track": dict(ep.meta)}

    # the methods below run after reset(), which sets self.episode (cast: typed Optional until then)
    def _window_bounds(self) -> tuple[int, int]:
        return self._start, min(self._start + self.config.window, len(cast(Episode, self.episode).y))

    def _run_window(self, params: dict[str, np.ndarray], carry: Any, end: int | None = None) -> tuple[np.ndarray, Any]:
        """Estimates (A, w, 4) of the current window (or, with ``end``, of the frames from its start to ``end``)
        for candidates ``params`` (arrays (A,)), continuing from ``carry`` (the back end's: a Kalman state or the
        FIR family's measurement history, :meth:`bboxtune.filters.base.Filter.run_from`), and the carry after them."""
        ep = cast(Episode, self.episode)
        start, window_end = self._window_bounds()
        end = window_end if end is None else end
        n = len(params["horizon"])
        flt = filters.make(self.config.backend, box_model(ep.tau), **{k: params[k] for k in ACCEPTS[self.config.backend]})
        y = detections(self.config.backend, ep.y[start:end])
        est, after = flt.positions_from(np.broadcast_to(y, (n, end - start, 4)), carry)
        return hold_missing(est, self._estimate[start - 1] if start > 0 else None), after  # the last box shown

    def _advance(self, params: dict[str, np.ndarray]) -> np.ndarray:
        est, self._carry = self._run_window(params, self._carry)
        start, end = self._window_bounds()
        self._estimate[start:end] = est[0]
        self._start = end
        return est

    def _features(self, lo: int, hi: int, msd: bool = False) -> np.ndarray:
        """``FEATURE_NAMES`` of the measurements [lo, hi) (pilot residual: the rule's estimates on them; ``msd``:
        :func:`measurement_features`'s)."""
        ep = cast(Episode, self.episode)
        return measurement_features(ep.y[lo:hi], ep.tau, ep.nominal.sigma_v, ep.nominal.sigma_w, self._rule_est[lo:hi],
                                    msd=msd)

    def _observe(self) -> np.ndarray:
        ep, start = cast(Episode, self.episode), self._start
        feats = self._features(max(0, start - self.config.history), start)
        last = max(0, start - self.config.window)
        recent = window_features(ep.y[last:start], self._estimate[last:start], self._rule_est[last:start])
        progress = np.float32(start / len(ep.y))
        parts = [feats, recent, self._action, [progress]]
        if self.config.retune_view == "offline":
            coming_start, coming_end = self._window_bounds()
            coming = self._features(coming_start, coming_end) if coming_start < coming_end else np.zeros(len(FEATURE_NAMES))
            parts += [coming, self._track_features]
        return np.concatenate(parts).astype(np.float32)

    def score(self, actions: np.ndarray) -> dict[str, np.ndarray]:
        """Score actions (A, d) on the *current window* (continuing from the current filter state) in one
        vectorised run; the same keys as FilterTune-v0's ``score`` (the window's scores; ``reward`` the step's
        reward, see Rewards) and ``track_so_far`` (A,), the track's reward up to the window's end ("track" rewards;
        None otherwise). Does not advance the episode."""
        if self.episode is None or self._start >= len(self.episode.y):
            raise RuntimeError("no window to score: call reset()")
        params = self.action_map.to_params(actions, self.episode.nominal, "actions")
        self._check_candidates(len(params["horizon"]), self._window_bounds()[1])
        est, _ = self._run_window(params, self._broadcast_carry(len(params["horizon"])))
        return self._score_window(est, params, *self._window_bounds())

    def score_rest(self, actions: np.ndarray) -> dict[str, np.ndarray]:
        """Score actions (A, d), each held for every remaining window, on the frames from the current window's
        start to the track's end (continuing from the current filter state, in one vectorised run; the same as
        stepping with the action to the end): ``reward`` (what stepping to the end would return in all: with
        "track" rewards the change of the track's reward, else the reward on those frames), the
        ``bboxtune.envs.episodes.scoring.SCORE_KEYS`` scores on those frames, ``params`` and ``estimates`` (A, T −
        start, 4). Does not advance
        the episode. One-shot tuning (one action from now on) is a search over this."""
        if self.episode is None or self._start >= len(self.episode.y):
            raise RuntimeError("no window to score: call reset()")
        params = self.action_map.to_params(np.atleast_2d(actions), self.episode.nominal, "actions")
        end = len(self.episode.y)
        self._check_candidates(len(params["horizon"]), end)
        est, _ = self._run_window(params, self._broadcast_carry(len(params["horizon"])), end)
        return self._score_window(est, params, self._start, end)

    def features_so_far(self, msd: bool = False) -> np.ndarray:
        """The FilterTune-v0 observation (``bboxtune.envs.episodes.features.FEATURE_NAMES``; ``msd=True``: and the
        "msd" feature set's last entry) of every frame filtered so far, [0, ``window_start``): the whole track's
        features as a one-shot tuner would see them if the track ended here (measurement-only; the pilot residual
        against the rule's estimates on those frames)."""
        if self.episode is None:
            raise RuntimeError("no episode: call reset()")
        return self._features(0, self._start, msd)

    @property
    def observation_names(self) -> tuple[str, ...]:
        """A name for every observation entry, in the Observation Space table's order."""
        return retune_observation_names(self.config)

    @property
    def window_start(self) -> int:
        """The first frame of the next window (the frames before it are filtered and observed)."""
        return self._start

    @property
    def rule_estimates(self) -> np.ndarray:
        """(T, 4) the fixed rule's boxes on the whole track (the reward's reference; causal filters, so its first
        frames depend only on the measurements up to them)."""
        if self.episode is None:
            raise RuntimeError("no episode: call reset()")
        return self._rule_est.copy()

    @property
    def estimates(self) -> np.ndarray:
        """(T, 4) the boxes estimated so far (the warm-up window by the rule; NaN beyond the last step)."""
        if self.episode is None:
            raise RuntimeError("no episode: call reset()")
        return self._estimate.copy()

    def _broadcast_carry(self, n: int) -> Any:
        return None if self._carry is None else self._carry.repeat(n)

    def _check_candidates(self, n: int, end: int) -> None:
        """Refuse ``n`` candidates on the frames from the window's start to ``end`` whose scoring would not fit in the
        available memory (``scoring.check_candidates``; "track" rewards score from the end of the warm-up)."""
        first = min(self.config.window, self._start) if self.config.retune_reward == "track" else self._start
        check_candidates(self.config.backend, n, end - first)

    def _score_window(self, est: np.ndarray, params: dict[str, np.ndarray], start: int, end: int) -> dict[str, Any]:
        truth = cast(Episode, self.episode).truth[start:end]
        scores = score_estimates(est, truth)
        rule = {k: float(v[0]) for k, v in score_estimates(self._rule_est[None, start:end], truth).items()}
        if self.config.retune_reward == "track":
            track = self._track_so_far(est, start, end)
            reward = track - self._track_reward
        else:
            track = None
            has_truth = np.isfinite(truth).all(axis=1).any()
            reward = reward_from(scores, rule, self.config.reward) if has_truth else np.zeros(len(est))
        return {"reward": reward, **scores, "params": params, "estimates": est, "rule": rule, "track_so_far": track}

    def _track_so_far(self, est: np.ndarray, start: int, end: int) -> np.ndarray:
        """The env's reward (against the rule) on the frames from the end of the warm-up to ``end``, for candidates
        whose estimates on [start, end) are ``est`` (A, end − start, 4) after the estimates already made (A,)."""
        ep = cast(Episode, self.episode)
        first = min(self.config.window, len(ep.y))  # the warm-up is the rule's on both sides
        truth = ep.truth[first:end]
        if not np.isfinite(truth).all(axis=1).any():
            return np.zeros(len(est))
        past = np.broadcast_to(self._estimate[first:start], (len(est), start - first, est.shape[-1]))
        scores = score_estimates(np.concatenate([past, est], axis=1), truth)
        rule = {k: float(v[0]) for k, v in score_estimates(self._rule_est[None, first:end], truth).items()}
        return reward_from(scores, rule, self.config.reward)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.episode is None or self._start >= len(self.episode.y):
            raise RuntimeError("episode is over: call reset()")
        a = self.action_map.check_one(action)
        params = self.action_map.to_params(a, self.episode.nominal)
        start, end = self._window_bounds()
        est = self._advance(params)
        result = self._score_window(est, params, start, end)
        if result["track_so_far"] is not None:
            self._track_reward = float(result["track_so_far"][0])
        self._action = a[0].astype(np.float32)
        info: dict[str, Any] = {k: float(result[k][0]) for k in SCORE_KEYS}
        info.update({f"rule_{k}": result["rule"][k] for k in SCORE_KEYS})
        info.update(n_frames=end - start, window=(start, end), track=dict(self.episode.meta),
                    params=self.physical(params), rule_params=self.physical(self._rule_params))
        terminated = end >= len(self.episode.y)
        if terminated:  # the truth only once every decision of the episode is made
            both = score_estimates(np.stack([self._estimate, self._rule_est]), self.episode.truth)["rmse"]
            info.update(track_rmse=float(both[0]), track_rule_rmse=float(both[1]), scenario=dict(self.episode.scenario))
        return self._observe(), float(result["reward"][0]), terminated, False, info

    def render(self) -> np.ndarray | None:
        return self._render(self._estimate, frame=max(self._start - 1, 0)) if self.episode is not None else None


def retune_observation_names(config: EnvConfig) -> tuple[str, ...]:
    """The FilterRetune-v0 observation's entries (Observation Space) for ``config``: ``FEATURE_NAMES`` (the recent
    frames), ``WINDOW_FEATURE_NAMES``, ``action_<parameter>`` per tuned parameter, ``progress`` and, with the offline
    view, ``coming_<feature>`` and ``track_<feature>``."""
    tune = cast("tuple[str, ...]", config.tune)  # EnvConfig.__post_init__ resolves None to the backend's default
    names = [*FEATURE_NAMES, *WINDOW_FEATURE_NAMES, *(f"action_{p}" for p in tune), "progress"]
    if config.retune_view == "offline":
        names += [*(f"coming_{n}" for n in FEATURE_NAMES), *(f"track_{n}" for n in FEATURE_NAMES)]
    return tuple(names)
