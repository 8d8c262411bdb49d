"""``bboxtune/FilterTune-v0``: tune a smoothing filter once per track (a contextual bandit)."""

from __future__ import annotations

from collections import deque
from typing import Any, cast

import numpy as np
from gymnasium.utils import seeding

from bboxtune.envs.episodes.actions import Nominal
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.features import measurement_features
from bboxtune.envs.episodes.scoring import (
    SCORE_KEYS,
    check_candidates,
    reference_scores,
    reward_from,
    run_positions,
    run_tracks,
    score_estimates,
    score_tracks,
)
from bboxtune.envs.track_env import TrackEnv, check_reset_args

Prepared = tuple[Episode, dict[str, Any], np.ndarray]  # an episode, its fixed-rule run and its observation


class FilterTuneEnv(TrackEnv):
    """
    ## Description
    One episode is one track of bounding boxes: a simulated constant-velocity box with Gauss–Markov coloured
    measurement noise (``source="sim"``), OTB-100 ground truth corrupted with such noise (``"otb"``), a
    real tracker's OTB-100 output (``"otb_tracker"``; the tracker drawn per episode from ``trackers``), a
    detector's boxes on a synthetic video (``"video"``), a MOT15 pedestrian measured by the public detections
    matched to it (``"mot"``, :mod:`bboxtune.envs.episodes.mot_source`) or, per episode, one of sim / otb / otb_tracker /
    mot drawn with ``mix_weights`` (``"mix"``: one policy for all of them). The agent sees a summary of the
    *measurements* and chooses the smoothing filter's parameters (ψ, horizon N, noise scales) for the whole
    track; the filter (``backend``) then runs over the track and the reward compares it with the fixed rule of
    the literature (N = N_opt(σ_v, σ_w, τ) with nominal σ, ψ = ``nominal_psi``; for ``bytetrack_kf`` the stock
    ByteTrack filter) on the same measurements.

    ## Action Space
    ``Box(-1, 1, (d,), float32)``, one entry per name in ``tune`` (default per back end:
    ``bboxtune.envs.episodes.actions.DEFAULT_TUNE``, e.g. ``("psi", "horizon")`` for ``ufir_cmn``):

    | parameter              | mapping from a ∈ [-1, 1]                          | range                   |
    |------------------------|---------------------------------------------------|-------------------------|
    | psi                    | ψ = 0.99 (a + 1) / 2                              | [0, 0.99]               |
    | horizon                | N = round(2 (N_max / 2)^((a + 1) / 2)), log scale | integers [2, N_max=400] |
    | sigma_w                | σ_w = nominal · 10^(1.5 a)                        | nominal · [0.03, 31.6]  |
    | sigma_v                | σ_v = nominal · 10^(1.5 a)                        | nominal · [0.03, 31.6]  |
    | std_weight_position    | σ_p = stock · 10^(1.5 a), stock 1/20              | stock · [0.03, 31.6]    |
    | std_weight_velocity    | σ_ṗ = stock · 10^(1.5 a), stock 1/160             | stock · [0.03, 31.6]    |
    | std_aspect_measurement | s_m = stock · 10^(1.5 a), stock 0.1               | stock · [0.03, 31.6]    |

    The last three are ``backend="bytetrack_kf"``'s (ByteTrack's / DeepSORT's box Kalman filter,
    :mod:`bboxtune.filters.bytetrack_kf`): its two std weights (noise relative to the box height; the default ``tune``)
    and, on request (``tune=(..., "std_aspect_measurement")``), the aspect ratio's measurement std. Their
    nominal is ByteTrack's published value in every episode, so the rule's action is stock ByteTrack and the
    reward (``reward_baseline="rule"``) is the gain over it. Scaling both weights by one factor scales the
    filter's Q, R and P₀ alike: the estimates depend on σ_ṗ / σ_p only (as OFIR's on σ_w / σ_v), and the width
    through the aspect ratio, which neither weight touches (a per-episode grid oracle's mean log-ratio over 60
    default sim episodes, whose aspect noise σ_ξ / size varies widely: 0.05 with the weights, 0.13 with s_m too;
    over 60 MOT15 pedestrian episodes 0.17 either way). ``sort_kf`` has no parameters to tune and is not a back end of the envs.

    ``bboxtune.envs.episodes.actions.ActionMap`` implements it both ways (``to_params`` / ``to_actions``). ``step`` takes
    exactly one action of shape (d,): any other shape (a batch (A, d) included) raises ``ValueError``, as do
    NaN/inf entries and entries outside [-1, 1] (entries within 1e-6 of it are accepted as float32
    round-off and clipped — nothing else is clipped); a non-numeric or bool dtype raises ``TypeError``.
    ``env.unwrapped.score(actions)`` takes a batch (A, d), A >= 1, with the same checks, and refuses one whose
    scoring would not fit in the available memory (``bboxtune.envs.data.memory``).

    "Trust the measurement" (no smoothing) is an action for every back end: N = 2 (a = -1), σ_w at the top
    (+1), σ_v at the bottom (-1), ψ = 0 (-1) for ``ufir_cmn`` and ψ = 0.99 (+1) for ``kf_cmn``. The estimates
    then equal the measurements exactly (to round-off) for ``ufir``, ``ufir_cmn``, ``oufir`` and ``fir``, and
    within 0.1 % of the box scale for ``kf_cmn`` (at most 3.2e-4 on simulated tracks). With the default
    ranges ``kf`` and ``ukf`` stay up to 7 % of the box scale away (simulated tracks at τ = 1/30 s; 0.2 % on
    tracker output) and ``ofir`` up to 32 % (17 %; its horizon-start prior ties the estimate to the previous
    measurement unless σ_w/σ_v is large); the opt-ins ``sigma_decades=2.5`` (``kf``, ``ukf``: within 1e-4)
    and ``tune=("horizon", "sigma_w", "sigma_v"), sigma_decades=2.5`` (``ofir``: within 2e-5) reach it
    (maxima of |estimate − y| / box scale over a track; tests/envs/test_trust_measurement.py). ``bytetrack_kf``
    (σ_p at -1, σ_ṗ at +1) follows cx, cy, h to 1e-4 of the box scale but keeps the stock aspect smoothing of w
    (up to 36 %; 5 % with s_m tuned too, at -1); with s_m tuned and ``sigma_decades=2.5`` it is within 1e-3
    (tests/envs/test_bytetrack_env.py).

    ## Observation Space
    ``Box(-inf, inf, (20,), float32)``: features of the measured boxes only, never the truth or the true
    ψ/σ — the table in ``bboxtune.envs.episodes.features`` (log box scale [log px], log τ [log s], log-variances of first and
    second differences of centre and size relative to scale², lag-1..3 autocorrelations of the differences,
    log N_opt from nominal and from estimated σ [log frames], the σ estimates, residual statistics of the
    fixed-rule filter, fraction of missing frames, log T). ``features="msd"`` appends a 21st entry,
    ``log_msd_pos``: the log mean squared displacement of the centre over 64 frames relative to scale² (at most half
    the track; ``bboxtune.envs.episodes.features.msd_feature``), which separates slow coloured noise from motion.
    ``scripts/train.py`` trains on it by default (its ``--features``).

    ## Rewards
    ``reward="rmse"`` (default): log(RMSE_rule / RMSE_action), RMSE over all frames with ground truth of the
    (cx, cy, w, h) error in px — scale-free, 0 means as good as the rule. ``"iou_precision"`` ([PaleRamon-BBox]'s
    TP/(TP+FP) averaged over 21 IoU thresholds) and ``"success_auc"`` (OTB success AUC): action minus rule.
    ``reward_baseline="raw"`` measures the same against the unfiltered measurements instead of the rule
    (log(RMSE_raw / RMSE), action minus raw): per episode the rewards move by a constant, so the best action
    and every method's ranking stay the same, but where the best filter stays close to the measurements (a
    strong tracker's output) the signal no longer carries the rule's large, episode-dependent loss.

    ## Starting State
    ``reset`` draws an episode: for ``sim`` a scenario (ψ ~ U(psi_range), σ_w, σ_ξ log-uniform over their ranges, τ
    ~ U(tau_range)) and its noise (``sim_noise="box"``: the ``otb`` source's box-relative CMN on the simulated
    truth, σ_rel log-uniform over ``cmn_rel_range``, with the OTB sources' nominal σ); for OTB sources a sequence of
    ``split`` (and for ``otb`` the CMN level and ψ; for ``otb_tracker`` first the tracker, uniformly from
    ``trackers``, then a sequence it has output for); for ``mot`` an identity of ``split`` (``"<sequence>/<id>"``);
    for ``mix`` first the part (sim / otb / otb_tracker / mot, probabilities ∝ ``mix_weights``), then that part's
    episode of the same noise seed. ``reset(options={"sequence": name, "noise_seed": s, "tracker": t})`` pins an
    episode (``sequence`` only for OTB, MOT and video sources and the OTB and MOT parts of a mix, ``tracker`` only
    for tracker episodes, one of the env's ``trackers``), so that different methods can be compared on identical
    data; ``noise_seed`` is an integer >= 0, ``sequence`` and ``tracker`` a str (None = not given); another key,
    type or value raises ``ValueError`` / ``TypeError`` naming the option, as does a ``seed`` that is not None or an
    integer >= 0. A rejected reset changes nothing: the env keeps its current episode and ``np_random``.
    ``env.unwrapped.source.sequences`` and ``.trackers`` list what an OTB source draws from
    (``sequences_of(tracker)``: one tracker's sequences; MEEM and MUSTer lack 27).

    ``reset``'s ``info`` is ``{"track": {...}}``: what identifies the episode — ``sequence``, ``noise_seed``,
    ``tau`` (also in the observation), ``tracker`` for ``otb_tracker``, ``detector`` and ``n_missing``
    (frames without a detection, visible in the measurements) for ``video``, ``first_frame`` (and ``stride`` /
    ``offset`` on the train split with ``otb_speedup_max`` > 1) for ``mot``, ``source`` (the part: ``"sim"``,
    ``"otb"``, ``"otb_tracker"`` or ``"mot"``) for ``mix`` — never the true scenario, which is revealed only in
    the step's ``info["scenario"]`` (see Episode End).

    Every episode is a pure function of its noise seed (and sequence, tracker); without options the seed is
    the next draw from ``np_random``; the sequence, tracker and mix part come from independent generators
    seeded with it (``bboxtune.envs.episodes.sources``), so passing ``info["track"]``'s sequence, noise_seed and tracker as
    options replays it. For speed the ``sim`` source draws and prepares (simulation, rule run, rule
    scores, observation) a block of up to 64 unpinned episodes at once — batched over the block — and hands
    them out one per reset: the episodes, their order and every value are the same as one at a time (the
    tests check bit-identity with the pinned episode for every back end), but ``np_random`` advances a block at
    a time. ``reset(seed=s)`` discards the prepared block, draws the next block's noise seeds and prepares its
    first episode (the rest together at the next unseeded reset); when ``s`` is the last reseed's seed + 1 it
    reads ahead, preparing the first episodes of seeds s + 1, s + 2, … with it (2, 4, … up to a block as the run
    grows), so an evaluation loop ``reset(seed=i)``, i = 0, 1, …, pays for blocks and scattered seeds for one
    episode each — ``reset(seed=s)`` gives a fresh env's episode either way, bit for bit (tested). A pinned
    episode is prepared alone and leaves the block as it is; with a ``seed`` it drops the block and restarts the
    unpinned sequence from it.

    ## Episode End
    After one step: ``terminated=True``, ``truncated=False``. ``info`` then holds, for the action and for the rule
    on the same episode: ``rmse``/``rule_rmse``, ``iou_mean``, ``success_auc``, ``precision20``, ``iou_precision``
    (each also with a ``rule_`` prefix), ``n_frames``, ``params`` and ``rule_params`` (the physical parameters
    applied), ``track`` (as at reset) and ``scenario``: the truth, now that the decision is made — ``psi``,
    ``sigma_w`` (px/s²), ``sigma_xi`` (px) for ``sim``; ``psi``, ``sigma_rel`` for ``otb``; empty for
    ``otb_tracker``, ``video`` and ``mot``; the part's for ``mix``. ``env.unwrapped.score(actions)`` scores many
    actions (A, d) on the current episode in one vectorised call and returns the same keys as arrays (A,) plus
    ``reward``. A step after the end raises ``RuntimeError`` (call ``reset``).

    ## Arguments
    Keyword arguments of ``gym.make`` are the fields of ``bboxtune.envs.episodes.config.EnvConfig`` plus ``render_mode``
    (``None`` or ``"rgb_array"``). Each is checked by type and range (its comment there states the allowed
    values): an unknown key or a wrong type raises ``TypeError``, a value out of range ``ValueError``, both
    naming the argument. ``track_length`` (sim and video) is at most 100,000 frames
    (``bboxtune.envs.episodes.config.TRACK_LENGTH_MAX``); simulated box sizes are reflected at ``box_size_bounds`` (default
    4 to 1000 px, ``bboxtune.envs.data.simulate``), so they stay plausible at any length.

    ``backend``: one of ``bboxtune.envs.episodes.actions.BACKENDS`` — the eight of ``bboxtune.filters.NAMES`` and
    ``"bytetrack_kf"``
    (Action Space); ``tune`` names parameters of ``bboxtune.envs.episodes.actions.ACCEPTS[backend]``.

    ``features``: the observation's feature set, ``"base"`` (default, 20 entries) or ``"msd"`` (21, Observation Space).

    ``trackers`` (``otb_tracker``, ``mix``): the tracker names an episode's tracker is drawn from (each must exist
    under the OTB root; None → ``(tracker,)``, the single-tracker env of before). The default tracker split is
    ``bboxtune.envs.data.otb.TRACKER_SPLIT``: ``"test"`` = SiamRPN++, CFNet, STRUCK, MDNet (held out, never trained
    on), ``"train"`` = the other 9. ``mix_weights``, a (sim, otb, otb_tracker) triple or a (sim, otb, otb_tracker,
    mot) 4-tuple, default (1, 1, 1): each part's relative probability (reals >= 0, sum > 0; a triple is mot weight 0
    and draws the episodes it drew before the mot part existed, bit for bit; a 4-tuple whose mot weight is 0 is
    stored as that triple). A part of weight 0 is never drawn and needs no data — OTB parts need ``otb_root`` /
    $OTB_ROOT, the mot part ``mot_root`` / $MOT_ROOT (MOT15: the identities of ``split``, the OTB split rule by
    sequence, ``bboxtune.envs.data.mot.split``; source ``mot`` with ``mot_holdout=SEQUENCE``: a
    leave-one-sequence-out fold, ``split="test"`` that sequence, train and val the others). Each part draws with the
    settings it takes (``bboxtune.envs.episodes.config.mix_part``): the sim settings and ``sim_noise`` /
    ``scenario`` only the sim part, ``otb_speedup_max`` the OTB and mot parts, the detection errors the sim, otb and
    otb_tracker parts — never the mot part, whose real detections keep their own misses. Arguments the source would
    not use are refused, not ignored: ``trackers`` with another source (or with ``mix_weights[2] == 0``),
    ``mix_weights`` other than the default without ``source="mix"``, ``mot_root`` without source ``mot`` or a
    positive mot weight (``mix_weights[3]``), detection errors with a mix of the mot part alone. Observation and
    action spaces do not depend on the source.

    ``otb_speedup_max`` (OTB sources, ``mot``, the OTB and mot parts of a mix; default 1: off): on the **train split
    only**, each episode plays every k-th frame of its sequence, k uniform in [1, otb_speedup_max] and a random
    offset, at the same τ — the same object moving k times as far per frame, an augmentation for motion faster than
    the training sequences show (a tuner that has only seen slow objects smooths fast ones away); k is lowered where
    fewer than 64 frames would remain. ``info["track"]`` then adds ``stride`` and ``offset``; val and test episodes
    (evaluation, model selection) always play every frame. With source ``mot`` and the mot part of a mix the stride
    plays the identity at fps / k with τ = k / fps (:mod:`bboxtune.envs.episodes.mot_source`).

    ``scenario`` (sim, and the sim part of a mix, with ``motion="cv"``): ``"stationary"`` (default) draws one ψ,
    σ_w, σ_ξ per track; ``"nonstationary"`` keeps that draw as the first regime and adds, within the track,
    1–3 switches of ψ and σ_ξ (redrawn from ``psi_range`` / ``sigma_xi_range``, at frames in [T/10, 9T/10)),
    0–3 manoeuvre bursts (σ_w × 10 for 20–100 frames) and 0–2 occlusion gaps (5–30 missing frames), all at
    random times (:mod:`bboxtune.envs.data.sim_regimes`). The schedule is revealed with the truth, in the step's
    ``info["scenario"]`` (``regimes``, ``manoeuvres``, ``gaps``; ``psi`` / ``sigma_xi`` there are the
    frame-weighted mean ψ and rms σ_ξ), never in the observation.

    Detection errors (sources ``sim``, ``otb``, ``otb_tracker`` and those parts of ``mix``; never the mot part of a
    mix; refused with ``video``, ``mot`` and a mix of the mot part alone, whose detectors miss already), to train on
    what a real detection stream looks like (MOT15 public detections miss 44 % of a pedestrian's frames on average,
    in runs of median 2 and up to 214 frames, and sometimes match a wrong box): ``detection_dropout`` — ``"none"``
    (default), ``"bernoulli"`` (each frame missed independently at the episode's miss rate) or ``"runs"`` (a
    Gilbert–Elliott chain: miss runs of mean length L frames, the stationary miss fraction equal to the rate; L is
    raised to rate / (1 − rate) where it could not reach it) — with the rate uniform in ``miss_rate_range`` (default
    (0, 0.6), within [0, 0.95]) and L log-uniform in ``miss_run_range`` (default (1, 20), within [1, 1000];
    ``"runs"`` only); and ``outlier_rate_range`` (default (0, 0): off, within [0, 0.5]), the per-episode
    probability, uniform, that a measured frame (with ground truth) shows a nearby object's box instead: the true
    box's size × a log-normal factor (log std 0.3), its centre 0.5–2 box heights away in a random direction (any
    ``detection_dropout``). A missed frame is a NaN row of the measurements (the filters predict through it; the
    truth is scored as before); the first and last measured frames always stay. The errors come from the episode's
    own generator ``(noise_seed, 5)`` (``bboxtune.envs.episodes.sources``): the episode is still a pure function of its seed,
    and the nominal σ of the OTB sources and ``sim_noise="box"`` come from the measurements left. The drawn
    ``miss_rate``, ``miss_run`` and ``outlier_rate`` are revealed in the step's ``info["scenario"]``; the
    observation's fraction of missing frames shows what was missed. Details: :mod:`bboxtune.envs.data.sim_detections`. A
    range that would not be used is refused, not ignored (``miss_rate_range`` without dropout, ``miss_run_range``
    without ``"runs"``).

    >>> import gymnasium as gym, envs
    >>> env = gym.make("bboxtune/FilterTune-v0", backend="ufir_cmn", source="sim", track_length=300)
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.action_space.shape, sorted(info["track"])
    ((20,), (2,), ['noise_seed', 'sequence', 'tau'])
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> terminated, truncated, info["n_frames"], sorted(info["scenario"])
    (True, False, 300, ['psi', 'sigma_w', 'sigma_xi'])

    ``gym.make`` does not wrap these envs in Gymnasium's ``PassiveEnvChecker`` (they are registered with
    ``disable_env_checker=True``): in Gymnasium 1.4 that wrapper fails every later ``step`` with a
    ``TypeError`` once its first ``reset`` has raised. The tests run Gymnasium's and SB3's full checkers.

    ## Version History
    * v0: initial version.
    * v0, hardened (no change to any default 500-frame ``sim`` episode, checked bit for bit): the true
      scenario moved from reset's ``info["track"]`` to the step's ``info["scenario"]``; arguments, reset
      options and actions are checked by type and range, a batch action in ``step`` is refused, and a
      rejected call leaves the env usable; simulated box sizes are reflected at ``box_size_bounds``
      (before, they grew without bound on long tracks: 1e13 px at 10,000 frames) and ``track_length`` is
      at most 100,000; no passive env checker by default.
    * v0, tracker sets and mix (no change to any episode of the earlier arguments, checked bit for bit):
      ``trackers`` (the tracker drawn per episode), the ``tracker`` reset option, ``source="mix"`` with
      ``mix_weights``, ``info["track"]["source"]`` for mix episodes, ``source.sequences`` / ``.trackers``;
      "trust the measurement" documented and tested per back end (Action Space).
    * v0, ``scenario="nonstationary"`` (the default stationary episodes unchanged bit for bit); a reseeded reset
      prepares one episode of its block, the rest at the next reset (the same episodes; ~27× → ~2.4× the cost
      of an unseeded reset in ``scripts/bench_env.py``).
    * v0, batched (no change to any FIR-family episode; Kalman-family values move by ~1e-15 relative): the
      registered ``vector_entry_point`` :class:`bboxtune.envs.vector.TuneVectorEnv` (``gym.make_vec`` /
      ``bboxtune.envs.make_vec``: n tracks per step in one batch); the fixed rule of ``kf`` / ``kf_cmn`` runs in frame
      units, so a block of tracks with different τ shares one filter call.
    * v0, ``reward_baseline`` (default ``"rule"``: no change to any reward) and ``sim_noise`` (default
      ``"absolute"``: no change to any episode).
    * v0, ``otb_speedup_max`` (default 1: no change to any episode).
    * v0: backend bytetrack_kf added (no change to existing episodes): ByteTrack's box Kalman filter with its two
      std weights (and, on request, the aspect's measurement std) tuned around the stock values.
    * v0, detection errors: ``detection_dropout``, ``miss_rate_range``, ``miss_run_range``, ``outlier_rate_range``
      (defaults: none, no change to any episode, checked bit for bit); ``info["scenario"]`` adds the drawn
      ``miss_rate`` / ``miss_run`` / ``outlier_rate`` when they are on.
    * v0, MOT15 in the mix (no change to any episode of the earlier arguments, checked bit for bit against the
      code before, ``tests/envs/test_mix_mot.py``): ``mix_weights`` takes a (sim, otb, otb_tracker, mot) 4-tuple,
      ``mot_root`` a mix with a positive mot weight, ``info["track"]["source"]`` is ``"mot"`` for its episodes; a
      mix with ``sim_noise="box"`` or ``scenario="nonstationary"`` and OTB weight, refused before by its OTB parts'
      configs, draws them (the sim part's settings; ``bboxtune.envs.episodes.config.mix_part``).
    * v0, ``features="msd"`` (the default ``"base"`` changes no observation): the centre's mean squared displacement
      over 64 frames as a 21st observation entry (with it PPO closes 91 % of the rule → oracle gap on the default
      scenario instead of 86 %; docs/results-sim.md).
    * v0, reseeding reads ahead (no change to any episode; ``bench_env.py`` [1b] ~1.75× → ~1.15×); a pinned reset with
      a ``seed`` restarts the unpinned sequence from it (before: the noise seeds of an earlier reseed's block).
    * v0, ``mot_holdout`` (default None: no change to any episode): leave-one-sequence-out folds of source ``mot``.
    """

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        super().__init__(0, render_mode=render_mode, **kwargs)
        self._rule: dict[str, Any] = {}
        self._ready: deque[Prepared] = deque()  # prepared, not yet used
        self._pending: deque[int] = deque()  # noise seeds of the current block drawn but not yet prepared
        self._ahead: dict[int, Prepared] = {}  # episodes read ahead, not yet used, by noise seed
        self._ahead_width = 0  # episodes the last read-ahead prepared
        self._last_seed: int | None = None  # the seed of the last unpinned reseeded reset
        self._estimate: np.ndarray | None = None
        self._done = True

    # -- episode ---------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        seed, options = check_reset_args(seed, options)
        block: list[Prepared] = []
        pending: list[int] = []
        ahead: tuple[dict[int, Prepared], int] | None = None
        with self._seeded(seed):
            if options:  # a pinned episode: prepared alone, the queue stays as it is
                prepared = self.prepare([self._draw(options)])[0]
            elif seed is None and self._ready:
                prepared = self._ready[0]
            elif seed is None:  # none left: the next block (its noise seeds drawn at a reseed, or now)
                block = self.prepare(self.source.draw_many(list(self._pending) or self._noise_seeds(self.source.block)))
                prepared = block[0]
            else:  # reseeded: the block is stale; its first episode now (and next seeds' read ahead), the rest later
                seeds = self._noise_seeds(self.source.block)
                ahead = self._read_ahead(seed, seeds[0])
                block, pending = [ahead[0][seeds[0]]], seeds[1:]
                prepared = block[0]
        # nothing below can fail: the env changes only once the new episode is ready
        if seed is not None:
            self._ready.clear()
            self._pending.clear()
        if block:
            self._ready.extend(block[1:])
            self._pending = deque(pending)
        elif not options:
            self._ready.popleft()
        if ahead is not None:
            (self._ahead, self._ahead_width), self._last_seed = ahead, seed
            del self._ahead[seeds[0]]  # each episode read ahead is handed out once
        self.episode, self._rule, self._obs = prepared
        self._estimate = None
        self._done = False
        return self._obs.copy(), {"track": dict(self.episode.meta)}

    def _read_ahead(self, seed: int, noise_seed: int) -> tuple[dict[int, Prepared], int]:
        """The episodes prepared for ``reset(seed=seed)``, by noise seed: ``noise_seed``'s (the first of the seed's
        block) and, when ``seed`` follows the last reseed's, those of the next seeds, 2, 4, … up to
        ``source.block`` of them in one batch (bit for bit the same: an episode is a function of its noise seed)."""
        if noise_seed in self._ahead:
            return self._ahead, self._ahead_width
        width = 1
        if self._last_seed is not None and seed == self._last_seed + 1:
            width = min(2 * self._ahead_width, self.source.block)
        noise_seeds = [noise_seed] + [self._noise_seeds(self.source.block, seeding.np_random(seed + j)[0])[0]
                                      for j in range(1, width)]
        return dict(zip(noise_seeds, self.prepare(self.source.draw_many(noise_seeds)), strict=True)), width

    def prepare(self, episodes: list[Episode]) -> list[Prepared]:
        """Each episode with its fixed-rule run (parameters, estimate, scores, and the ``reference`` scores the
        reward is measured against: the rule's or the raw measurements', ``reward_baseline``) and its observation — batched
        over episodes of equal length (the rule's filter runs, its scores and the features)."""
        stacked = Nominal.stacked([ep.nominal for ep in episodes])  # the rule's parameters, a row per episode
        rule_params = [{k: v[r:r + 1] for k, v in stacked.items()} for r in range(len(episodes))]  # each rule_params(ep)
        estimates = run_tracks(self.config.backend, [ep.y for ep in episodes], [ep.tau for ep in episodes], stacked)
        truths = [ep.truth for ep in episodes]
        scores = score_tracks(estimates, truths)
        reference = reference_scores(self.config.reward_baseline, scores, [ep.y for ep in episodes], truths)
        out: list[Prepared] = [None] * len(episodes)  # type: ignore[list-item]
        scores_of = {k: v.tolist() for k, v in scores.items()}  # Python floats, converted once for all episodes
        reference_of = {k: v.tolist() for k, v in reference.items()}
        lengths: dict[int, list[int]] = {}  # the episodes of each length, in order
        for r, ep in enumerate(episodes):
            lengths.setdefault(len(ep.y), []).append(r)
        for _, rows in sorted(lengths.items()):  # the features of equal-length tracks in one call
            nominal = [episodes[r].nominal for r in rows]
            obs = measurement_features(np.stack([episodes[r].y for r in rows]), [episodes[r].tau for r in rows],
                                       [n.sigma_v for n in nominal], [n.sigma_w for n in nominal],
                                       np.stack([estimates[r] for r in rows]), msd=self.config.features == "msd")
            for i, r in enumerate(rows):
                rule = {"params": rule_params[r], "estimate": estimates[r],
                        "scores": {k: v[r] for k, v in scores_of.items()},
                        "reference": {k: v[r] for k, v in reference_of.items()}}
                out[r] = (episodes[r], rule, obs[i])
        return out

    def score(self, actions: np.ndarray) -> dict[str, Any]:
        """Score actions (A, d) on the current episode in one vectorised filter run.

        Returns ``reward``, ``rmse``, ``iou_mean``, ``success_auc``, ``precision20``, ``iou_precision``
        (arrays (A,)) and ``params`` (dict of arrays (A,)); equal to what :meth:`step` returns per action. A
        batch whose scoring would not fit in the available memory (``scoring.check_candidates``: A × T × a few
        hundred bytes) raises ``bboxtune.envs.data.memory.MemoryLimitError``, a ``ValueError``, before any filter runs."""
        if self.episode is None:
            raise RuntimeError("call reset() before score()")
        params = self.action_map.to_params(actions, self.episode.nominal, "actions")
        check_candidates(self.config.backend, len(params["horizon"]), len(self.episode.y))
        est = run_positions(self.config.backend, self.episode.y, self.episode.tau, params)
        scores = score_estimates(est, self.episode.truth)
        return {"reward": reward_from(scores, self._rule["reference"], self.config.reward), **scores,
                "params": params, "estimates": est}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._done:
            raise RuntimeError("episode is over (one step per episode): call reset()")
        result = self.score(self.action_map.check_one(action))
        self._estimate = result["estimates"][0]
        self._done = True
        info = self.step_info(result)
        return self._obs.copy(), float(result["reward"][0]), True, False, info

    def step_info(self, result: dict[str, Any], row: int = 0, prepared: tuple[Episode, dict[str, Any]] | None = None
                  ) -> dict[str, Any]:
        """The step's ``info`` for candidate ``row`` of ``result`` (:meth:`score`'s keys) on the current episode
        or on ``prepared`` = (episode, rule run) (a batch of episodes, :mod:`bboxtune.envs.vector`)."""
        episode, rule = prepared or (cast(Episode, self.episode), self._rule)  # after reset() or a prepared one
        info: dict[str, Any] = {k: float(result[k][row]) for k in SCORE_KEYS}
        info.update({f"rule_{k}": rule["scores"][k] for k in SCORE_KEYS})
        info["n_frames"] = int(len(episode.y))
        info["params"] = self.physical(result["params"], row)
        info["rule_params"] = self.physical(rule["params"])
        info["track"] = dict(episode.meta)
        info["scenario"] = dict(episode.scenario)  # the truth, now that the decision is made
        return info

    def render(self) -> np.ndarray | None:
        return self._render(self._estimate if self._estimate is not None else self._rule.get("estimate"))
