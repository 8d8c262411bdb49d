"""Episode sources: where a track comes from (simulator, OTB ground truth + CMN, real tracker output).

Every episode is a pure function of ``(sequence, noise_seed)`` (and ``tracker`` for "otb_tracker"): the env
draws the noise seed from its own ``np_random`` and the source derives the rest from it (the sequence, the
tracker, the part of a "mix") unless ``reset(options=...)`` pins them, so paired comparisons can replay
exactly the same episode. The generators: ``default_rng(noise_seed)`` the sim scenario and noise,
``(noise_seed, 0)`` the OTB sequence, ``(noise_seed, 1)`` the "otb" CMN, ``(noise_seed, 2)`` the tracker,
``(noise_seed, 3)`` the part of a "mix", ``(noise_seed, 4)`` the frame stride of an OTB training episode
(``otb_speedup_max``), ``(noise_seed, 5)`` the detection errors (``detection_dropout``, ``outlier_rate_range``:
missed frames and wrong boxes, :mod:`bboxtune.envs.data.sim_detections`) — independent streams, so adding trackers, a
mix or detection errors changes none of the others.

Detection errors (sources "sim", "otb", "otb_tracker" and those parts of "mix"; not "video", "mot" or the mot
part of a mix, whose detectors already miss) are added to an episode's measured boxes after its noise and before
its nominal σ, which the OTB sources and ``sim_noise="box"`` take from the measured boxes — from what the agent
sees. The
episode's ``scenario`` gains their drawn ``miss_rate``, ``miss_run``, ``outlier_rate``
(:meth:`bboxtune.envs.data.sim_detections.DetectionModel.parameters`). Without them (the defaults) nothing is drawn
from stream 5 and every episode is what it was.

An episode keeps what identifies it (``meta``: sequence, noise seed, τ, tracker — shown to the agent at
reset) apart from the true scenario that generated its noise (``scenario``: ψ, σ_w, σ_ξ or the relative
CMN level — revealed only after the agent's decision, in the step info).

Minimum length: a source draws only episodes of at least ``min_frames`` frames (2 by default;
FilterRetune-v0 asks for two windows with :meth:`Source.require_frames`). Sources of one fixed length
(``n_frames``: sim, video) reject a shorter one there; the OTB sources leave shorter sequences out of the
pool — an unpinned draw re-draws the sequence from the same generator (so every seed whose first pick is long
enough keeps its sequence), and pinning a shorter one raises ``ValueError``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, cast

import numpy as np

from bboxtune.envs.data.boxes import cxcywh_to_xywh
from bboxtune.envs.data.otb import OTBDataset, replay_synthetic, replay_tracker, split
from bboxtune.envs.data.scenario_ranges import ScenarioRanges
from bboxtune.envs.data.sim_detections import DetectionModel
from bboxtune.envs.data.sim_regimes import simulate_nonstationary
from bboxtune.envs.data.simulate import Scenario, Track, simulate_each
from bboxtune.envs.episodes.actions import K_AXIS, Nominal
from bboxtune.envs.episodes.config import MIX_SOURCES, EnvConfig, mix_part
from bboxtune.envs.episodes.episode import Episode, Source, rule_nominal
from bboxtune.envs.episodes.features import box_scale
from bboxtune.envs.episodes.mot_source import MOTSource
from bboxtune.envs.episodes.video_source import VideoSource
from bboxtune.filters.horizon import rule_horizon

SPEEDUP_MIN_FRAMES = 64  # frames an OTB training episode keeps at the least when played at a stride > 1


def _log_uniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    lo, hi = lo_hi
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _detected(cfg: EnvConfig, noise_seeds: list[int], ys: list[np.ndarray], truths: list[np.ndarray]
              ) -> tuple[list[np.ndarray], list[dict[str, float]]]:
    """The measured boxes ``ys`` (equal lengths) of the episodes of ``noise_seeds`` with the config's detection
    errors (module docstring), drawn together from each episode's ``default_rng((noise_seed, 5))``, and each
    episode's drawn parameters for its ``scenario``; ``ys`` themselves and no parameters without errors."""
    model = DetectionModel(cfg.detection_dropout, cfg.miss_rate_range, cfg.miss_run_range, cfg.outlier_rate_range)
    if not model.active:
        return ys, [{} for _ in ys]
    drawn = model.draw([np.random.default_rng((seed, 5)) for seed in noise_seeds], len(ys[0]))
    y, _, _ = model.apply(np.stack(ys), np.stack(truths), drawn)
    return list(y), model.parameters(drawn)


class SimSource(Source):
    """Simulated CV boxes with Gauss–Markov CMN (:mod:`bboxtune.envs.data.simulate`); the scenario is drawn per episode
    from the config's ranges. Nominal σ are the geometric centres of the σ ranges."""

    def __init__(self, cfg: EnvConfig) -> None:
        self.cfg = cfg
        self.ranges = ScenarioRanges(
            psi=cfg.psi_range, sigma_w=cfg.sigma_w_range, sigma_xi=cfg.sigma_xi_range, tau=cfg.tau_range,
            n_frames=(cfg.track_length, cfg.track_length), size=cfg.box_size_range, ndim=4,
            size_bounds=cfg.box_size_bounds, motion=cfg.motion,
        )
        self.n_frames = cfg.track_length
        self.block = max(1, min(64, 2**15 // cfg.track_length))  # episodes FilterTune-v0 prepares at once
        self.sigma_v_nominal = float(np.sqrt(np.prod(cfg.sigma_xi_range)))
        self.sigma_w_nominal = float(np.sqrt(np.prod(cfg.sigma_w_range)))

    def draw(self, sequence: str | None, noise_seed: int) -> Episode:
        if sequence is not None:
            raise ValueError(f"options['sequence']={sequence!r}: the 'sim' source has no sequences; pin episodes with noise_seed")
        return self.draw_many([noise_seed])[0]

    def draw_many(self, noise_seeds: list[int]) -> list[Episode]:
        """The episodes of ``noise_seeds``, simulated in one vectorised pass (:func:`bboxtune.envs.data.simulate.simulate_each`:
        each equal to drawing it alone)."""
        if not noise_seeds:
            return []
        rngs = [np.random.Generator(np.random.PCG64(seed)) for seed in noise_seeds]  # default_rng(seed), in half the time
        scenarios = [self.ranges.sample(rng) for rng in rngs]
        if self.cfg.scenario == "nonstationary":
            episodes = [self._nonstationary(seed, scenario) for seed, scenario in zip(noise_seeds, scenarios, strict=False)]
            ys, drawn = _detected(self.cfg, noise_seeds, [ep.y for ep in episodes], [ep.truth for ep in episodes])
            return [replace(ep, y=y, scenario={**ep.scenario, **d}) for ep, y, d in zip(episodes, ys, drawn, strict=False)]
        tracks = simulate_each(scenarios, rngs)
        horizons = cast(np.ndarray, rule_horizon(self.sigma_v_nominal, self.sigma_w_nominal, np.array([t.tau for t in tracks]),
                                                 K_AXIS, max_horizon=self.cfg.horizon_max))  # one per track
        truths = [self._truth(scenario, track) for scenario, track in zip(scenarios, tracks, strict=False)]
        ys = [track.y for track in tracks]
        if self.cfg.sim_noise == "box":
            ys = [self._box_noise(seed, scenario.psi, track, truth)
                  for seed, scenario, track, truth in zip(noise_seeds, scenarios, tracks, truths, strict=False)]
        ys, drawn = _detected(self.cfg, noise_seeds, ys, [track.truth for track in tracks])
        episodes = []
        for seed, scenario, track, horizon, y, truth, d in zip(noise_seeds, scenarios, tracks, horizons.tolist(), ys,
                                                               truths, drawn, strict=False):
            meta = {"sequence": None, "noise_seed": seed, "tau": scenario.tau}
            if self.cfg.sim_noise == "box":  # the OTB sources' nominal σ, relative to the measured box scale
                scale = cast(float, box_scale(y))  # of one track (T, 4)
                nominal = rule_nominal(self.cfg, self.cfg.otb_sigma_v_rel * scale, self.cfg.otb_sigma_w_rel * scale,
                                       track.tau)
            else:
                nominal = Nominal(sigma_w=self.sigma_w_nominal, sigma_v=self.sigma_v_nominal, psi=self.cfg.nominal_psi,
                                  horizon=horizon)
            episodes.append(Episode(truth=track.truth, y=y, tau=track.tau, nominal=nominal, meta=meta,
                                    scenario={**truth, **d}))
        return episodes

    @staticmethod
    def _truth(scenario: Scenario, track: Track) -> dict[str, Any]:
        """The episode's true scenario (its ``scenario`` before ``sim_noise="box"`` and detection errors)."""
        truth: dict[str, Any] = {"psi": scenario.psi, "sigma_w": scenario.sigma_w, "sigma_xi": scenario.sigma_xi}
        if scenario.motion == "otb":  # σ_w: the rms true centre acceleration, the CV model's equivalent
            acceleration = np.diff(track.truth_state[:, 4:6], axis=0) / track.tau
            truth.update(sigma_w=float(np.sqrt(np.mean(acceleration**2))), motion="otb",
                         velocity_rms=scenario.velocity_rms, size_rw=scenario.size_rw)
        return truth

    def _box_noise(self, seed: int, psi: float, track: Track, truth: dict[str, Any]) -> np.ndarray:
        """``sim_noise="box"``: the measurements (T, 4) of the simulated truth, taken as the "otb" source measures
        OTB ground truth (:func:`bboxtune.envs.data.otb.replay_synthetic`: CMN of ψ and a σ_rel log-uniform in
        ``cmn_rel_range``, from
        ``default_rng((seed, 1))``, scaled by the true box); ``truth`` gains ``sigma_rel`` (its ``sigma_xi`` is
        then the unused absolute draw's, removed). The nominal σ are the OTB sources' (:meth:`draw_many`)."""
        rng = np.random.default_rng((seed, 1))
        sigma_rel = _log_uniform(rng, self.cfg.cmn_rel_range)
        measured = replay_synthetic(cxcywh_to_xywh(track.truth), psi=psi, sigma_rel=sigma_rel, rng=rng, tau=track.tau)
        truth.pop("sigma_xi")
        truth.update(sigma_rel=sigma_rel, noise="box")
        return measured.y

    def _nonstationary(self, seed: int, scenario: Scenario) -> Episode:
        """The nonstationary episode of ``seed`` around its drawn ``scenario`` (:mod:`bboxtune.envs.data.sim_regimes`)."""
        track, truth = simulate_nonstationary(scenario, seed, self.cfg.psi_range, self.cfg.sigma_xi_range)
        nominal = rule_nominal(self.cfg, self.sigma_v_nominal, self.sigma_w_nominal, track.tau)
        return Episode(truth=track.truth, y=track.y, tau=track.tau, nominal=nominal,
                       meta={"sequence": None, "noise_seed": seed, "tau": scenario.tau}, scenario=truth)


class OTBSource(Source):
    """OTB-100 sequences of one split: ground truth + synthetic CMN ("otb") or a tracker's output
    ("otb_tracker"). Nominal σ are the config's relative values times the measured box scale.

    "otb_tracker": an episode's tracker is drawn uniformly from ``trackers`` (``cfg.trackers``, None →
    ``(cfg.tracker,)``) with ``default_rng((noise_seed, 2))``, then its sequence from that tracker's pool — the
    split's sequences it has output for (MEEM and MUSTer lack 27 of OTB-100) — with ``(noise_seed, 0)`` as for
    "otb"; with one tracker this is the draw of a single-tracker env, bit for bit. A pinned tracker skips its
    draw; a pinned sequence with an unpinned tracker re-draws the tracker from the same generator until it
    has output for the sequence. ``sequences``: the pool (long enough sequences of the split with output of
    some tracker), ``sequences_of(t)``: tracker ``t``'s pool."""

    def __init__(self, cfg: EnvConfig, dataset: OTBDataset | None = None) -> None:
        self.cfg = cfg
        self.dataset = dataset if dataset is not None else OTBDataset(cfg.otb_root)
        names = split(self.dataset.names)[cfg.split]
        self._pools: dict[str | None, tuple[str, ...]] = {None: names}
        if cfg.source == "otb_tracker":
            self.trackers = cfg.trackers if cfg.trackers is not None else (cfg.tracker,)
            unknown = [t for t in self.trackers if t not in self.dataset.trackers]
            if unknown:
                field_name = "tracker" if cfg.trackers is None else "trackers"
                raise ValueError(f"{field_name}={getattr(cfg, field_name)!r}: {unknown} not found under "
                                 f"{self.dataset.trackers_root}; allowed: {self.dataset.trackers}")
            have = {t: set(self.dataset.tracker_sequences(t)) for t in self.trackers}
            self._pools = {t: tuple(n for n in names if n in have[t]) for t in self.trackers}
        empty = [t for t, pool in self._pools.items() if not pool]
        if empty:
            which = f" for tracker(s) {empty}" if cfg.source == "otb_tracker" else ""
            raise ValueError(f"no sequences in split {cfg.split!r} for source {cfg.source!r}{which}")
        pooled = set().union(*self._pools.values())
        self.names = tuple(n for n in names if n in pooled)  # the split's sequences with output of some tracker
        self._long_enough = frozenset(self.names)  # the pool: sequences of at least min_frames frames

    @property
    def sequences(self) -> tuple[str, ...]:
        """The sequences episodes are drawn from (split order): of the split, long enough, with tracker output."""
        return tuple(n for n in self.names if n in self._long_enough)

    def sequences_of(self, tracker: str) -> tuple[str, ...]:
        """Tracker ``tracker``'s pool ("otb_tracker"): the sequences its episodes are drawn from."""
        if tracker not in self.trackers:
            raise ValueError(f"tracker {tracker!r} is not one of this source's trackers {self.trackers}")
        return tuple(n for n in self._pools[tracker] if n in self._long_enough)

    def max_frames(self) -> int:
        """The frames of the pool's longest sequence (every frame: a stride only shortens an episode)."""
        return max(len(self.dataset.groundtruth(name)) for name in self.sequences)

    def require_frames(self, n: int, why: str) -> None:
        """Leave the sequences shorter than ``n`` frames out of the pool (documented in the module docstring)."""
        long_enough = frozenset(name for name in self.names if len(self.dataset.groundtruth(name)) >= n)
        if not long_enough:
            raise ValueError(f"no sequence of split {self.cfg.split!r} has the {n} frames {why} needs")
        short = [t for t, pool in self._pools.items() if long_enough.isdisjoint(pool)]
        if short:
            raise ValueError(f"no sequence of split {self.cfg.split!r} with output of tracker(s) {short} has the "
                             f"{n} frames {why} needs")
        self._long_enough = long_enough
        self.min_frames = n

    def pick(self, rng: np.random.Generator, tracker: str | None = None) -> str:
        """A sequence of the pool (of ``tracker``), uniformly: names are drawn from ``rng`` until one is long enough."""
        names = self._pools[tracker]
        while True:
            name = str(names[rng.integers(len(names))])
            if name in self._long_enough:
                return name

    def _pick_tracker(self, rng: np.random.Generator, sequence: str | None) -> str:
        """A tracker of the set, uniformly; for a pinned ``sequence`` re-drawn until it has output for it."""
        having = [t for t in self.trackers if sequence is None or sequence in self.dataset.tracker_sequences(t)]
        if not having:
            raise ValueError(f"options['sequence']={sequence!r}: none of the trackers {self.trackers} has output for it")
        while True:
            tracker = str(self.trackers[rng.integers(len(self.trackers))])
            if tracker in having:
                return tracker

    def draw(self, sequence: str | None, noise_seed: int, tracker: str | None = None) -> Episode:
        cfg = self.cfg
        if sequence is not None and sequence not in self.dataset.names:
            raise ValueError(f"options['sequence']={sequence!r} is not an OTB sequence under {self.dataset.root}")
        if tracker is not None and tracker not in self.trackers:
            raise ValueError(f"options['tracker']={tracker!r}; allowed: one of this env's trackers {self.trackers}")
        if cfg.source == "otb_tracker" and tracker is None:
            tracker = self._pick_tracker(np.random.default_rng((noise_seed, 2)), sequence)
        name = sequence if sequence is not None else self.pick(np.random.default_rng((noise_seed, 0)), tracker)
        gt = self.dataset.groundtruth(name)
        if len(gt) < self.min_frames:
            raise ValueError(f"options['sequence']={name!r} has {len(gt)} frames; this env needs at least "
                             f"{self.min_frames} (sequences shorter than that are left out of its pool)")
        meta: dict[str, Any] = {"sequence": name, "noise_seed": noise_seed, "tau": cfg.otb_tau}
        frames = slice(None)
        if cfg.otb_speedup_max > 1 and cfg.split == "train":
            frames = self._speedup(len(gt), noise_seed)
            meta.update(stride=frames.step, offset=frames.start)
        scenario: dict[str, Any] = {}
        if cfg.source == "otb":
            rng = np.random.default_rng((noise_seed, 1))  # independent of the sequence pick above
            psi = float(rng.uniform(*cfg.psi_range))
            sigma_rel = _log_uniform(rng, cfg.cmn_rel_range)
            track = replay_synthetic(gt[frames], psi=psi, sigma_rel=sigma_rel, rng=rng, tau=cfg.otb_tau)
            scenario.update(psi=psi, sigma_rel=sigma_rel)
        else:
            boxes = self.dataset.tracker_boxes(cast(str, tracker), name)  # otb_tracker: picked above if not given
            track = replay_tracker(gt[frames], boxes[frames], tau=cfg.otb_tau)
            meta.update(tracker=tracker)
        (y,), (drawn,) = _detected(cfg, [noise_seed], [track.y], [track.truth])
        scale = cast(float, box_scale(y))  # of one track (T, 4)
        nominal = rule_nominal(cfg, cfg.otb_sigma_v_rel * scale, cfg.otb_sigma_w_rel * scale, track.tau)
        return Episode(truth=track.truth, y=y, tau=track.tau, nominal=nominal, meta=meta, scenario={**scenario, **drawn})

    def _speedup(self, n_frames: int, noise_seed: int) -> slice:
        """The frames a training episode of ``n_frames`` plays (class docstring): every k-th from offset j."""
        rng = np.random.default_rng((noise_seed, 4))
        drawn = int(rng.integers(1, self.cfg.otb_speedup_max + 1))
        stride = max(1, min(drawn, n_frames // max(SPEEDUP_MIN_FRAMES, self.min_frames)))  # every offset keeps n // k
        offset = int(rng.integers(stride))
        return slice(offset, None, stride)


class MixSource(Source):
    """Source "mix": each episode's part — "sim", "otb", "otb_tracker" or "mot"
    (``bboxtune.envs.episodes.config.MIX_SOURCES``) — is drawn with probabilities proportional to ``mix_weights`` from
    ``default_rng((noise_seed, 3))``; the episode is then that part's episode of the same noise seed (what a
    single-source env of the part draws, with the config :func:`bboxtune.envs.episodes.config.mix_part` gives it: nominal σ,
    the fixed rule and the scenario come from the part; the detection errors apply to the sim / otb / otb_tracker
    parts, never to the mot part's real detections), with ``meta["source"]`` naming the part. A (sim, otb,
    otb_tracker) triple draws the part over those three as before the mot part existed (the same episodes bit for
    bit). Parts of weight 0 are not built (without OTB weight no OTB data is needed, without mot weight no MOT15
    data). Each part keeps its split: the OTB parts draw the ``split``'s sequences, the mot part its identities
    (:func:`bboxtune.envs.data.mot.split`). Pinning a sequence (an OTB sequence or a MOT identity "<sequence>/<id>") or a
    tracker is allowed when the noise seed draws a part that has them; the part is never re-drawn, so the options of
    an episode's ``meta`` replay it."""

    def __init__(self, cfg: EnvConfig) -> None:
        self.weights = np.array(cfg.mix_weights) / sum(cfg.mix_weights)  # 3 entries for a triple: its draw of before
        self.parts: dict[str, Source] = {}
        weights = cfg.mix_parts
        dataset = None
        if weights["otb"] > 0 or weights["otb_tracker"] > 0:
            try:
                dataset = OTBDataset(cfg.otb_root)
            except ValueError as err:
                raise ValueError(f"source='mix' with mix_weights={cfg.mix_weights!r} draws OTB episodes and needs the "
                                 f"OTB data (give the otb parts weight 0 to mix without it): {err}") from None
        for name, weight in weights.items():
            if weight > 0:
                part = mix_part(cfg, name)
                self.parts[name] = (SimSource(part) if name == "sim" else _mot_part(cfg, part) if name == "mot" else
                                    OTBSource(part, dataset))
        self.block = self.parts["sim"].block if "sim" in self.parts else 1
        self.trackers = self.parts["otb_tracker"].trackers if "otb_tracker" in self.parts else ()

    def max_frames(self) -> int:
        """The longest episode of any part."""
        return max(part.max_frames() for part in self.parts.values())

    def require_frames(self, n: int, why: str) -> None:
        for part in self.parts.values():
            part.require_frames(n, why)
        self.min_frames = n

    def part_of(self, noise_seed: int) -> str:
        """The part that the episode of ``noise_seed`` comes from."""
        return MIX_SOURCES[int(np.random.default_rng((noise_seed, 3)).choice(len(self.weights), p=self.weights))]

    def draw(self, sequence: str | None, noise_seed: int, tracker: str | None = None) -> Episode:
        part = self.part_of(noise_seed)
        for option, value, allowed in (("sequence", sequence, ("otb", "otb_tracker", "mot")),
                                       ("tracker", tracker, ("otb_tracker",))):
            if value is not None and part not in allowed:
                raise ValueError(f"options[{option!r}]={value!r}: noise_seed={noise_seed} draws a {part!r} episode of "
                                 f"source 'mix' (mix_weights), which has no {option}s; allowed with parts {allowed}")
        pinned = {"tracker": tracker} if tracker is not None else {}
        return _labelled(self.parts[part].draw(sequence, noise_seed, **pinned), part)

    def draw_many(self, noise_seeds: list[int]) -> list[Episode]:
        """The episodes of ``noise_seeds`` (the sim ones simulated in one vectorised pass), in order."""
        parts = [self.part_of(seed) for seed in noise_seeds]
        sim = iter(self.parts["sim"].draw_many([s for s, p in zip(noise_seeds, parts, strict=False) if p == "sim"])
                   if "sim" in self.parts else [])
        return [_labelled(next(sim) if p == "sim" else self.parts[p].draw(None, s), p)
                for s, p in zip(noise_seeds, parts, strict=False)]


def _mot_part(cfg: EnvConfig, part: EnvConfig) -> MOTSource:
    """The mot part (config ``part``) of the mix ``cfg``; a missing MOT15 copy is one error naming what needs it."""
    try:
        return MOTSource(part)
    except ValueError as err:
        raise ValueError(f"source='mix' with mix_weights={cfg.mix_weights!r} draws MOT episodes and needs the MOT15 "
                         f"data (mot_root or $MOT_ROOT; give the mot part weight 0 to mix without it): {err}") from None


def _labelled(episode: Episode, part: str) -> Episode:
    return replace(episode, meta={**episode.meta, "source": part})


def make_source(cfg: EnvConfig) -> Source:
    """The episode source of ``cfg.source`` (a :class:`Source`)."""
    if cfg.source == "sim":
        return SimSource(cfg)
    if cfg.source == "video":
        return VideoSource(cfg)
    if cfg.source == "mix":
        return MixSource(cfg)
    if cfg.source == "mot":
        return MOTSource(cfg)
    return OTBSource(cfg)
