"""Episode sources: where a track comes from (simulator, OTB ground truth + CMN, real tracker output).

Every episode is a pure function of ``(sequence, noise_seed)``: the env draws the noise seed (and for OTB
the sequence) from its own ``np_random`` unless ``reset(options=...)`` pins them, so paired comparisons
can replay exactly the same episode.

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

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from envs.actions import Nominal
from envs.config import EnvConfig
from envs.features import box_scale
from filters.horizon import rule_horizon

K_AXIS = 2  # state size of one coordinate's constant-velocity model


@dataclass(frozen=True)
class Episode:
    """One track to be filtered: boxes are (cx, cy, w, h) in px."""

    truth: np.ndarray  # (T, 4) true boxes; NaN rows: no ground truth (excluded from scores)
    y: np.ndarray  # (T, 4) measured boxes; NaN rows: missing detection
    tau: float  # s, frame interval the filters assume
    nominal: Nominal  # the fixed rule's parameters for this episode (from measurements / config only)
    meta: dict[str, Any] = field(default_factory=dict)  # what identifies it: sequence, noise_seed, tau, …
    scenario: dict[str, Any] = field(default_factory=dict)  # the true ψ, σ that made the noise (hidden until the step)


def _log_uniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    lo, hi = lo_hi
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _nominal(cfg: EnvConfig, sigma_v: float, sigma_w: float, tau: float) -> Nominal:
    horizon = rule_horizon(sigma_v, sigma_w, tau, K_AXIS, max_horizon=cfg.horizon_max)
    return Nominal(sigma_w=sigma_w, sigma_v=sigma_v, psi=cfg.nominal_psi, horizon=int(horizon))


class Source:
    """What the environments draw episodes from: ``draw(sequence, noise_seed)`` (subclasses) and
    ``draw_many(noise_seeds)``, the unpinned episodes of those seeds; ``block`` is how many of them
    FilterTune-v0 draws and prepares at once; ``n_frames`` the length of every episode when it is fixed."""

    block = 1
    n_frames: int | None = None
    min_frames = 2

    def require_frames(self, n: int, why: str) -> None:
        """Draw only episodes of at least ``n`` frames (``why``: what needs them, for the error message).
        A fixed ``n_frames`` below ``n`` raises ``ValueError`` naming ``track_length``."""
        if self.n_frames is not None and self.n_frames < n:
            raise ValueError(f"track_length={self.n_frames} is too short: {why} needs at least {n} frames")
        self.min_frames = n

    def draw(self, sequence: str | None, noise_seed: int) -> Episode:
        raise NotImplementedError

    def draw_many(self, noise_seeds: list[int]) -> list[Episode]:
        """``[draw(None, s) for s in noise_seeds]`` (sources with a batched form override it)."""
        return [self.draw(None, s) for s in noise_seeds]


class SimSource(Source):
    """Simulated CV boxes with Gauss–Markov CMN (:mod:`envs.simulate`); the scenario is drawn per episode
    from the config's ranges. Nominal σ are the geometric centres of the σ ranges."""

    def __init__(self, cfg: EnvConfig) -> None:
        from envs.simulate import ScenarioRanges

        self.cfg = cfg
        self.ranges = ScenarioRanges(
            psi=cfg.psi_range, sigma_w=cfg.sigma_w_range, sigma_xi=cfg.sigma_xi_range, tau=cfg.tau_range,
            n_frames=(cfg.track_length, cfg.track_length), size=cfg.box_size_range, ndim=4,
            size_bounds=cfg.box_size_bounds,
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
        """The episodes of ``noise_seeds``, simulated in one vectorised pass (:func:`envs.simulate.simulate_each`:
        each equal to drawing it alone)."""
        from envs.simulate import simulate_each

        rngs = [np.random.default_rng(seed) for seed in noise_seeds]
        scenarios = [self.ranges.sample(rng) for rng in rngs]
        tracks = simulate_each(scenarios, rngs)
        horizons = rule_horizon(self.sigma_v_nominal, self.sigma_w_nominal, np.array([t.tau for t in tracks]), K_AXIS,
                                max_horizon=self.cfg.horizon_max)
        episodes = []
        for seed, scenario, track, horizon in zip(noise_seeds, scenarios, tracks, horizons.tolist()):
            meta = {"sequence": None, "noise_seed": seed, "tau": scenario.tau}
            truth = {"psi": scenario.psi, "sigma_w": scenario.sigma_w, "sigma_xi": scenario.sigma_xi}
            nominal = Nominal(sigma_w=self.sigma_w_nominal, sigma_v=self.sigma_v_nominal, psi=self.cfg.nominal_psi,
                              horizon=horizon)
            episodes.append(Episode(truth=track.truth, y=track.y, tau=track.tau, nominal=nominal, meta=meta,
                                    scenario=truth))
        return episodes


class OTBSource(Source):
    """OTB-100 sequences of one split: ground truth + synthetic CMN ("otb") or a tracker's output
    ("otb_tracker"). Nominal σ are the config's relative values times the measured box scale."""

    def __init__(self, cfg: EnvConfig) -> None:
        from envs.otb import OTBDataset, split

        self.cfg = cfg
        self.dataset = OTBDataset(cfg.otb_root)
        names = split(self.dataset.names)[cfg.split]
        if cfg.source == "otb_tracker":
            if cfg.tracker not in self.dataset.trackers:
                raise ValueError(f"tracker={cfg.tracker!r} not found under {self.dataset.root}; allowed: {self.dataset.trackers}")
            have = set(self.dataset.tracker_sequences(cfg.tracker))
            names = tuple(n for n in names if n in have)
        if not names:
            raise ValueError(f"no sequences in split {cfg.split!r} for source {cfg.source!r}")
        self.names = names
        self._long_enough = frozenset(names)  # the pool: sequences of at least min_frames frames

    def require_frames(self, n: int, why: str) -> None:
        """Leave the sequences shorter than ``n`` frames out of the pool (documented in the module docstring)."""
        self._long_enough = frozenset(name for name in self.names if len(self.dataset.groundtruth(name)) >= n)
        if not self._long_enough:
            raise ValueError(f"no sequence of split {self.cfg.split!r} has the {n} frames {why} needs")
        self.min_frames = n

    def pick(self, rng: np.random.Generator) -> str:
        """A sequence of the pool, uniformly: names are drawn from ``rng`` until one is long enough."""
        while True:
            name = str(self.names[rng.integers(len(self.names))])
            if name in self._long_enough:
                return name

    def draw(self, sequence: str | None, noise_seed: int) -> Episode:
        from envs.otb import replay_synthetic, replay_tracker

        name = sequence if sequence is not None else self.pick(np.random.default_rng((noise_seed, 0)))
        if name not in self.dataset.names:
            raise ValueError(f"options['sequence']={name!r} is not an OTB sequence under {self.dataset.root}")
        gt = self.dataset.groundtruth(name)
        if len(gt) < self.min_frames:
            raise ValueError(f"options['sequence']={name!r} has {len(gt)} frames; this env needs at least "
                             f"{self.min_frames} (sequences shorter than that are left out of its pool)")
        cfg = self.cfg
        meta: dict[str, Any] = {"sequence": name, "noise_seed": noise_seed, "tau": cfg.otb_tau}
        scenario: dict[str, Any] = {}
        if cfg.source == "otb":
            rng = np.random.default_rng((noise_seed, 1))  # independent of the sequence pick above
            psi = float(rng.uniform(*cfg.psi_range))
            sigma_rel = _log_uniform(rng, cfg.cmn_rel_range)
            track = replay_synthetic(gt, psi=psi, sigma_rel=sigma_rel, rng=rng, tau=cfg.otb_tau)
            scenario.update(psi=psi, sigma_rel=sigma_rel)
        else:
            track = replay_tracker(gt, self.dataset.tracker_boxes(cfg.tracker, name), tau=cfg.otb_tau)
            meta.update(tracker=cfg.tracker)
        scale = box_scale(track.y)
        nominal = _nominal(cfg, cfg.otb_sigma_v_rel * scale, cfg.otb_sigma_w_rel * scale, track.tau)
        return Episode(truth=track.truth, y=track.y, tau=track.tau, nominal=nominal, meta=meta, scenario=scenario)


def make_source(cfg: EnvConfig) -> Source:
    """The episode source of ``cfg.source`` (a :class:`Source`)."""
    if cfg.source == "sim":
        return SimSource(cfg)
    if cfg.source == "video":
        from envs.video.source import VideoSource

        return VideoSource(cfg)
    return OTBSource(cfg)
