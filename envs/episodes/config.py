"""Configuration of the bboxtune environments: one frozen dataclass, keyword arguments of ``gym.make``.

Every field is checked on construction, type first, then range: a wrong type raises ``TypeError`` and a value
out of range ``ValueError``, both naming the field and what is allowed (``track_length="100"`` is a type
error, not a conversion; integers must be ``int`` or a numpy integer, ``bool`` is not one; ranges are
(low, high) pairs of real numbers). The allowed ranges are the comments below; they keep every simulated
quantity finite and physically plausible (see ``TRACK_LENGTH_MAX``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from bboxtune.envs.data.sim_detections import DROPOUTS
from bboxtune.envs.episodes.actions import ACCEPTS, BACKENDS, DEFAULT_TUNE
from bboxtune.envs.video.detectors import DETECTORS

SOURCES = ("sim", "otb", "otb_tracker", "video", "mix", "mot")
# the parts of source "mix", in the order of mix_weights (a triple: mot weight 0; mix_part: what each part takes)
MIX_SOURCES = ("sim", "otb", "otb_tracker", "mot")
SPLITS = ("train", "val", "test")
SCENARIOS = ("stationary", "nonstationary")  # sim: one regime per track, or regimes switching within it
REWARDS = ("rmse", "iou_precision", "success_auc")
FEATURE_SETS = ("base", "msd")  # EnvConfig.features
# Longest track (frames). Simulated box sizes are reflected at ``box_size_bounds`` (bboxtune.envs.data.simulate), so they
# stay plausible at any length; the bound keeps a track's memory and filter time moderate (a 100,000-frame
# episode: 3.2 MB per (T, 4) array; reset + step ~0.8 s with ufir_cmn, ~2 s with kf_cmn or ukf on a 2-core
# machine) and centre excursions well resolved in float64 (default ranges: at most 3.3e7 px from the start
# over 200 such episodes, where float64 resolves 1e-8 px).
TRACK_LENGTH_MAX = 100_000


def check_integer(name: str, value: Any, low: int, high: int) -> int:
    """``value`` as an int if it is an integer (not a bool) in [low, high]; else TypeError / ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}={value!r} has type {type(value).__name__}; allowed: an integer in [{low}, {high}]")
    if not low <= value <= high:
        raise ValueError(f"{name}={value!r} is out of range; allowed: an integer in [{low}, {high}]")
    return int(value)


def check_real(name: str, value: Any, low: float, high: float, *, open_low: bool = False) -> float:
    """``value`` as a float if it is a real number in [low, high] (or (low, high] with ``open_low``)."""
    interval = f"{'(' if open_low else '['}{low:g}, {high:g}]"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}={value!r} has type {type(value).__name__}; allowed: a real number in {interval}")
    try:
        v = float(value)
    except OverflowError:  # an int beyond float range
        v = math.inf
    if not (math.isfinite(v) and (low < v if open_low else low <= v) and v <= high):
        raise ValueError(f"{name}={value!r} is out of range; allowed: a real number in {interval}")
    return v


def check_range(name: str, value: Any, low: float, high: float, *, open_low: bool = False) -> tuple[float, float]:
    """A (low, high) pair of reals within [low, high] (``open_low``: low excluded) with pair[0] <= pair[1]."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) or len(value) != 2:
        raise TypeError(f"{name}={value!r}; allowed: a (low, high) pair of real numbers")
    lo, hi = (check_real(f"{name}[{i}]", v, low, high, open_low=open_low) for i, v in enumerate(value))
    if lo > hi:
        raise ValueError(f"{name}={value!r}; allowed: low <= high")
    return lo, hi


def check_choice(name: str, value: Any, allowed: Sequence[str]) -> str:
    """``value`` if it is one of the strings ``allowed``."""
    if not isinstance(value, str):
        raise TypeError(f"{name}={value!r} has type {type(value).__name__}; allowed: one of {tuple(allowed)}")
    if value not in allowed:
        raise ValueError(f"{name}={value!r}; allowed: one of {tuple(allowed)}")
    return value


def _optional_path(name: str, value: Any) -> str | None:
    if value is None:
        return None
    if not isinstance(value, (str, os.PathLike)) or not os.fspath(value):
        raise TypeError(f"{name}={value!r}; allowed: None or a non-empty path (str or os.PathLike)")
    return os.fspath(value)


def _trackers(value: Any) -> tuple[str, ...] | None:
    """None, or a non-empty sequence of distinct non-empty tracker names as a tuple (whether each exists
    under the OTB root is checked by the source, which reads it)."""
    if value is None:
        return None
    if (isinstance(value, str) or not isinstance(value, (Sequence, np.ndarray))
            or not all(isinstance(t, str) and t for t in value)):
        raise TypeError(f"trackers={value!r}; allowed: None or a sequence of tracker names (non-empty str)")
    trackers = tuple(str(t) for t in value)
    if not trackers or len(set(trackers)) != len(trackers):
        raise ValueError(f"trackers={trackers!r}; allowed: None or at least one tracker name, each at most once")
    return trackers


def _mix_weights(value: Any) -> tuple[float, ...]:
    """The weights as floats: the (sim, otb, otb_tracker) triple, or the 4-tuple with a positive mot weight (a mot
    weight of 0 is dropped: one value per mix, so the configs of before compare and draw as they did)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) or len(value) not in (3, 4):
        raise TypeError(f"mix_weights={value!r}; allowed: a (sim, otb, otb_tracker) triple or a (sim, otb, otb_tracker, "
                        "mot) 4-tuple of real numbers in [0, 1e6]")
    weights = tuple(check_real(f"mix_weights[{i}]", v, 0.0, 1e6) for i, v in enumerate(value))
    if not sum(weights) > 0:
        raise ValueError(f"mix_weights={value!r}; allowed: weights >= 0 with a positive sum")
    return weights[:3] if weights[3:] == (0.0,) else weights


def _tune(backend: str, value: Any) -> tuple[str, ...]:
    if value is None:
        return DEFAULT_TUNE[backend]
    if isinstance(value, str) or not isinstance(value, (Sequence, np.ndarray)) or not all(isinstance(p, str) for p in value):
        raise TypeError(f"tune={value!r}; allowed: None or a sequence of names from {ACCEPTS[backend]}")
    tune = tuple(value)
    if not tune or len(set(tune)) != len(tune) or any(p not in ACCEPTS[backend] for p in tune):
        raise ValueError(f"tune={tune!r} for backend {backend!r}; allowed: distinct names from {ACCEPTS[backend]}")
    return tune


@dataclass(frozen=True)
class EnvConfig:
    """Every argument of ``bboxtune/FilterTune-v0`` and ``bboxtune/FilterRetune-v0`` (units, allowed values)."""

    # "sim" | "otb" (GT + synthetic CMN) | "otb_tracker" (real tracker output) | "video" | "mix" | "mot" (MOT15 public
    # detections matched to ground-truth identities, bboxtune.envs.episodes.mot_source)
    source: str = "sim"
    backend: str = "ufir_cmn"  # any name in bboxtune.envs.episodes.actions.BACKENDS: bboxtune.filters.NAMES and "bytetrack_kf"
    reward: str = "rmse"  # "rmse": log(RMSE_rule / RMSE); "iou_precision" / "success_auc": difference to the rule
    # FilterTune-v0: what the reward is measured against, "rule" | "raw" (the unfiltered measurements: the same best
    # action per episode, a lower-variance signal where the filter should stay near the measurements)
    reward_baseline: str = "rule"
    # FilterTune-v0's observation: "base" (the 20 bboxtune.envs.episodes.features.FEATURE_NAMES) | "msd" (those and
    # MSD_FEATURE, the log mean squared displacement of the centre over MSD_LAG frames: bboxtune.envs.episodes.features)
    features: str = "base"
    tune: tuple[str, ...] | None = None  # parameters the agent sets; None -> bboxtune.envs.episodes.actions.DEFAULT_TUNE[backend]
    track_length: int = 500  # frames per simulated track / video, integer in [8, TRACK_LENGTH_MAX]
    # sim scenario distribution ((low, high); log-uniform for σ, uniform otherwise)
    psi_range: tuple[float, float] = (0.0, 0.95)  # within [0, 0.99]
    sigma_w_range: tuple[float, float] = (1.0, 100.0)  # px/s², acceleration noise std of cx, cy; within [1e-3, 1e4]
    sigma_xi_range: tuple[float, float] = (0.5, 10.0)  # px, std of the white noise ξ driving the CMN; within [1e-3, 1e3]
    tau_range: tuple[float, float] = (1 / 30, 0.1)  # s, frame interval; within [1e-3, 1]
    box_size_range: tuple[float, float] = (20.0, 200.0)  # px, initial w and h; within box_size_bounds
    box_size_bounds: tuple[float, float] = (4.0, 1000.0)  # px, simulated w and h are reflected here; within [1, 1e5]
    # sim truth motion: "cv" (constant velocity, σ_w above) | "otb" (fitted to OTB-100,
    # bboxtune.envs.data.sim_motion: scale-relative
    # velocity with manoeuvres, log-size random walk; sigma_w_range then only sets the rule's nominal σ_w)
    motion: str = "cv"
    # sim "stationary": one ψ, σ_w, σ_ξ per track | "nonstationary": regime switches of ψ and σ_ξ, manoeuvre bursts
    # and occlusion gaps within a track (bboxtune.envs.data.sim_regimes, documented with its ranges); sim / mix with motion "cv"
    scenario: str = "stationary"
    # sim measurement noise: "absolute" (CMN of σ_ξ px from sigma_xi_range added to the boxes; nominal σ the centres
    # of the σ ranges) | "box" (the "otb" source's noise on the simulated truth: box-relative CMN, σ_rel from
    # cmn_rel_range; nominal σ = otb_sigma_v_rel / otb_sigma_w_rel × the measured box scale); sim / mix, stationary
    sim_noise: str = "absolute"
    # detection errors of a real detection stream, added to the measurements (bboxtune.envs.data.sim_detections; sources sim,
    # otb, otb_tracker and the sim / otb / otb_tracker parts of mix, not video, mot or the mot part of a mix, whose
    # detectors already miss): missed frames (NaN rows of y, the first and last measured frame kept) — "none" |
    # "bernoulli" (each frame missed independently at the episode's miss rate) | "runs" (Gilbert–Elliott miss runs
    # of mean length miss_run at that rate)
    detection_dropout: str = "none"
    miss_rate_range: tuple[float, float] = (0.0, 0.6)  # fraction of frames missed, per episode, uniform; within [0, 0.95]
    miss_run_range: tuple[float, float] = (1.0, 20.0)  # frames, mean miss run ("runs"), log-uniform; within [1, 1000]
    # probability that a measured frame's box is a wrong match (a nearby object's box: bboxtune.envs.data.sim_detections), per
    # episode, uniform; with any detection_dropout; within [0, 0.5]
    outlier_rate_range: tuple[float, float] = (0.0, 0.0)
    # OTB sources
    otb_root: str | None = None  # folder of the OTB data; None -> $OTB_ROOT
    split: str = "train"  # "train" | "val" | "test": which sequences episodes are drawn from
    tracker: str = "SiamFC"  # source "otb_tracker": whose output is the measurement (a non-empty name)
    # "otb_tracker" / "mix": the trackers an episode's tracker is drawn from, uniformly (names under the OTB
    # root's trackers/, distinct; bboxtune.envs.data.otb.TRACKER_SPLIT has the default split); None -> (tracker,)
    trackers: tuple[str, ...] | None = None
    # source "mix": relative weights of its parts, a (sim, otb, otb_tracker) triple or a (sim, otb, otb_tracker, mot)
    # 4-tuple, each a real in [0, 1e6], sum > 0; a mot weight of 0 is stored as the triple (the same mix: one value)
    mix_weights: tuple[float, ...] = (1.0, 1.0, 1.0)
    # source "mot" or a mix with a positive mot weight: folder of the MOT15 data (bboxtune.envs.data.mot); None -> $MOT_ROOT
    mot_root: str | None = None
    # source "mot": one sequence held out (leave-one-sequence-out folds, bboxtune.envs.data.mot.holdout_split): split
    # "test" draws its identities, "train" and "val" those of every other sequence; None -> the split rule by sequence
    mot_holdout: str | None = None
    otb_tau: float = 1 / 30  # s, OTB frame interval (30 fps); in [1e-3, 1]
    # OTB sources, train split only (augmentation for fast motion): each episode plays its sequence at a random frame
    # stride k in [1, otb_speedup_max] (bboxtune.envs.episodes.sources.OTBSource), so the object moves k times as far per frame
    # (source "mot" and the mot part of a mix too: its identities are then played at fps / k, τ = k / fps,
    # bboxtune.envs.episodes.mot_source);
    # the val and test splits always play every frame; integer in [1, 8]
    otb_speedup_max: int = 1
    cmn_rel_range: tuple[float, float] = (0.01, 0.1)  # source "otb": σ_ξ relative to the box size, log-uniform; within [1e-4, 1]
    otb_sigma_v_rel: float = 0.03  # nominal σ_v relative to the measured box scale (OTB sources); in (0, 10]
    otb_sigma_w_rel: float = 3.0  # 1/s², nominal σ_w relative to the measured box scale (OTB sources); in (0, 1e4]
    # source "video": synthetic videos measured by a real detector (bboxtune.envs.episodes.video_source.VideoSource)
    detector: str = "template"  # one of bboxtune.envs.video.detectors.DETECTORS
    video_pool: int = 64  # distinct videos per split, integer in [1, 1e6]
    video_cache: str | None = None  # folder caching rendered + detected videos; None: memory only
    video_size: tuple[int, int] = (320, 240)  # px, frame width and height, integers in [64, 4096]
    video_sigma_v_rel: float | None = None  # nominal σ_v / box scale in (0, 10]; None: the detector's calibrated value
    video_sigma_w_rel: float | None = None  # 1/s², nominal σ_w / box scale in (0, 1e4]; None: calibrated value
    # action mapping
    horizon_max: int = 400  # frames, largest FIR horizon the agent can choose, integer in [2, 10000]
    sigma_decades: float = 1.5  # σ scales span nominal · 10^[-D, D], D in (0, 3]
    nominal_psi: float = 0.0  # ψ the fixed rule assumes (the white-noise rule of the literature); in [0, 0.99]
    # FilterRetune-v0
    window: int = 50  # frames per re-tuning step, integer in [8, TRACK_LENGTH_MAX // 2]
    history: int = 100  # frames of past measurements the re-tuning observation summarises, in [8, TRACK_LENGTH_MAX]
    # "track": a step's reward is the change of the reward of the track so far (its returns add up to the whole
    # track's reward, the evaluation's metric) | "window": the reward of the step's window alone
    retune_reward: str = "track"
    # what a re-tuning step observes: "causal" (the frames already filtered: a filter behind a live tracker) |
    # "offline" (a recorded track, all of whose measurements exist before the filter runs: the observation adds the
    # measurement features of the coming window and of the whole track, bboxtune.envs.retune_env)
    retune_view: str = "causal"

    def __post_init__(self) -> None:
        put = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen: normalised values)
        put("source", check_choice("source", self.source, SOURCES))
        put("mix_weights", _mix_weights(self.mix_weights))
        put("backend", check_choice("backend", self.backend, BACKENDS))
        put("reward", check_choice("reward", self.reward, REWARDS))
        put("reward_baseline", check_choice("reward_baseline", self.reward_baseline, ("rule", "raw")))
        put("features", check_choice("features", self.features, FEATURE_SETS))
        put("split", check_choice("split", self.split, SPLITS))
        put("motion", check_choice("motion", self.motion, ("cv", "otb")))
        put("scenario", check_choice("scenario", self.scenario, SCENARIOS))
        put("retune_reward", check_choice("retune_reward", self.retune_reward, ("track", "window")))
        put("retune_view", check_choice("retune_view", self.retune_view, ("causal", "offline")))
        put("sim_noise", check_choice("sim_noise", self.sim_noise, ("absolute", "box")))
        if self.sim_noise == "box" and (self.source not in ("sim", "mix") or self.scenario != "stationary"):
            raise ValueError(f"sim_noise='box' with source={self.source!r}, scenario={self.scenario!r}: allowed only "
                             "with source 'sim' or 'mix' (its sim part) and scenario 'stationary'")
        put("detection_dropout", check_choice("detection_dropout", self.detection_dropout, DROPOUTS))
        put("miss_rate_range", check_range("miss_rate_range", self.miss_rate_range, 0.0, 0.95))
        put("miss_run_range", check_range("miss_run_range", self.miss_run_range, 1.0, 1000.0))
        put("outlier_rate_range", check_range("outlier_rate_range", self.outlier_rate_range, 0.0, 0.5))
        detector = ("with source 'sim', 'otb', 'otb_tracker', or 'mix' with a positive sim, otb or otb_tracker weight "
                    "(the video and mot detectors, also a mix's mot part, miss and err already)")
        simulated = self.source in ("sim", "otb", "otb_tracker") or (
            self.source == "mix" and any(self.mix_parts[part] > 0 for part in MIX_SOURCES[:3]))
        for name, default, used, allowed in (
                ("detection_dropout", "none", simulated, detector),
                ("outlier_rate_range", (0.0, 0.0), simulated, detector),
                ("miss_rate_range", (0.0, 0.6), self.detection_dropout != "none",
                 "with detection_dropout 'bernoulli' or 'runs'"),
                ("miss_run_range", (1.0, 20.0), self.detection_dropout == "runs", "with detection_dropout 'runs'")):
            if getattr(self, name) != default and not used:
                raise ValueError(f"{name}={getattr(self, name)!r} with source={self.source!r}, detection_dropout="
                                 f"{self.detection_dropout!r}: allowed only {allowed}; leave the default {default!r} otherwise")
        if self.scenario == "nonstationary" and (self.source not in ("sim", "mix") or self.motion != "cv"):
            raise ValueError(f"scenario='nonstationary' with source={self.source!r}, motion={self.motion!r}: allowed "
                             "only with source 'sim' or 'mix' (its sim part) and motion 'cv'")
        put("tune", _tune(self.backend, self.tune))
        put("track_length", check_integer("track_length", self.track_length, 8, TRACK_LENGTH_MAX))
        put("window", check_integer("window", self.window, 8, TRACK_LENGTH_MAX // 2))
        put("history", check_integer("history", self.history, 8, TRACK_LENGTH_MAX))
        put("horizon_max", check_integer("horizon_max", self.horizon_max, 2, 10_000))
        put("video_pool", check_integer("video_pool", self.video_pool, 1, 1_000_000))
        put("psi_range", check_range("psi_range", self.psi_range, 0.0, 0.99))
        put("sigma_w_range", check_range("sigma_w_range", self.sigma_w_range, 1e-3, 1e4))
        put("sigma_xi_range", check_range("sigma_xi_range", self.sigma_xi_range, 1e-3, 1e3))
        put("tau_range", check_range("tau_range", self.tau_range, 1e-3, 1.0))
        put("box_size_bounds", check_range("box_size_bounds", self.box_size_bounds, 1.0, 1e5))
        lo, hi = self.box_size_bounds
        if not lo < hi:
            raise ValueError(f"box_size_bounds={self.box_size_bounds!r}; allowed: low < high")
        put("box_size_range", check_range("box_size_range", self.box_size_range, 0.0, math.inf))
        if not lo <= self.box_size_range[0] <= self.box_size_range[1] <= hi:
            raise ValueError(f"box_size_range={self.box_size_range!r} must lie within box_size_bounds={self.box_size_bounds!r}")
        put("cmn_rel_range", check_range("cmn_rel_range", self.cmn_rel_range, 1e-4, 1.0))
        put("otb_tau", check_real("otb_tau", self.otb_tau, 1e-3, 1.0))
        put("otb_speedup_max", check_integer("otb_speedup_max", self.otb_speedup_max, 1, 8))
        if self.otb_speedup_max > 1 and self.source not in ("otb", "otb_tracker", "mix", "mot"):
            raise ValueError(f"otb_speedup_max={self.otb_speedup_max} with source={self.source!r}: allowed only with "
                             "source 'otb', 'otb_tracker', 'mix' (its OTB and MOT parts) or 'mot'; leave the default 1 "
                             "otherwise")
        put("otb_sigma_v_rel", check_real("otb_sigma_v_rel", self.otb_sigma_v_rel, 0.0, 10.0, open_low=True))
        put("otb_sigma_w_rel", check_real("otb_sigma_w_rel", self.otb_sigma_w_rel, 0.0, 1e4, open_low=True))
        put("sigma_decades", check_real("sigma_decades", self.sigma_decades, 0.0, 3.0, open_low=True))
        put("nominal_psi", check_real("nominal_psi", self.nominal_psi, 0.0, 0.99))
        put("otb_root", _optional_path("otb_root", self.otb_root))
        put("mot_root", _optional_path("mot_root", self.mot_root))
        put("video_cache", _optional_path("video_cache", self.video_cache))
        if not isinstance(self.tracker, str) or not self.tracker:
            raise TypeError(f"tracker={self.tracker!r}; allowed: a non-empty tracker name (str)")
        self._check_mix_fields()
        self._check_video_fields()

    @property
    def mix_parts(self) -> dict[str, float]:
        """The weight of each part of source "mix" (``MIX_SOURCES`` order; the mot part's is 0 for a triple)."""
        weights = self.mix_weights + (0.0,) * (len(MIX_SOURCES) - len(self.mix_weights))
        return dict(zip(MIX_SOURCES, weights, strict=False))

    def _check_mix_fields(self) -> None:
        """``trackers`` checked; it, ``mix_weights`` (normalised first of all) and ``mot_root`` refused where the source
        would not use them."""
        object.__setattr__(self, "trackers", _trackers(self.trackers))
        mix = self.source == "mix"
        uses_trackers = self.source == "otb_tracker" or (mix and self.mix_parts["otb_tracker"] > 0)
        if self.trackers is not None and not uses_trackers:
            raise ValueError(f"trackers={self.trackers!r} with source={self.source!r}: allowed only with source "
                             "'otb_tracker', or 'mix' with a positive otb_tracker weight (mix_weights[2])")
        if not mix and self.mix_weights != (1.0, 1.0, 1.0):
            raise ValueError(f"mix_weights={self.mix_weights!r} with source={self.source!r}: allowed only with "
                             "source 'mix' (leave the default (1.0, 1.0, 1.0) otherwise)")
        if self.mot_holdout is not None and (self.source != "mot" or not isinstance(self.mot_holdout, str)
                                             or not self.mot_holdout):
            raise ValueError(f"mot_holdout={self.mot_holdout!r} with source={self.source!r}: allowed only with source "
                             "'mot', a sequence name (str)")
        if self.mot_root is not None and not (self.source == "mot" or (mix and self.mix_parts["mot"] > 0)):
            weights = f", mix_weights={self.mix_weights!r}" if mix else ""
            raise ValueError(f"mot_root={self.mot_root!r} with source={self.source!r}{weights}: allowed only with "
                             "source 'mot', or 'mix' with a positive mot weight (mix_weights[3])")

    def _check_video_fields(self) -> None:
        object.__setattr__(self, "detector", check_choice("detector", self.detector, DETECTORS))
        size = self.video_size
        if isinstance(size, (str, bytes)) or not isinstance(size, (Sequence, np.ndarray)) or len(size) != 2:
            raise TypeError(f"video_size={size!r}; allowed: a (width, height) pair of integers in [64, 4096]")
        object.__setattr__(self, "video_size", tuple(check_integer(f"video_size[{i}]", v, 64, 4096) for i, v in enumerate(size)))
        for name, high in (("video_sigma_v_rel", 10.0), ("video_sigma_w_rel", 1e4)):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, check_real(name, getattr(self, name), 0.0, high, open_low=True))

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> EnvConfig:
        """Build from ``gym.make`` keyword arguments; an unknown key raises ``TypeError`` naming it."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(kwargs) - known)
        if unknown:
            raise TypeError(f"unknown env argument(s) {unknown}; allowed: {sorted(known)}")
        return cls(**kwargs)


SIM_ONLY = ("sim_noise", "scenario")  # settings of the sim part that the OTB and MOT sources refuse other than default
DETECTION_ERRORS = ("detection_dropout", "miss_rate_range", "miss_run_range", "outlier_rate_range")


def mix_part(cfg: EnvConfig, part: str) -> EnvConfig:
    """The config that part ``part`` (of ``MIX_SOURCES``) of the mix ``cfg`` draws its episodes with: ``cfg`` as the
    part's own single source, so that a mix episode is the part's episode of the same noise seed.

    What applies to which part — every part: ``split`` (the sim part's is its noise seeds), the back end, reward,
    ``tune`` and action settings, ``nominal_psi``, ``horizon_max``;

    * sim: the sim settings (``track_length``, the ranges, ``motion``, ``scenario``, ``sim_noise`` with
      ``cmn_rel_range`` and the OTB sources' nominal), the detection errors; not ``otb_speedup_max`` (played at 1);
    * otb, otb_tracker: ``otb_root``, ``otb_tau``, ``otb_speedup_max``, the nominal ``otb_sigma_v_rel`` /
      ``otb_sigma_w_rel``, the detection errors; otb also ``psi_range`` and ``cmn_rel_range`` (its CMN),
      otb_tracker ``trackers``; ``sim_noise`` and ``scenario`` are the sim part's (here their defaults);
    * mot: ``mot_root``, ``otb_speedup_max`` (its frame strides on the train split) and the nominal ``otb_sigma_v_rel``
      / ``otb_sigma_w_rel`` (:mod:`bboxtune.envs.episodes.mot_source`); **no detection errors** — its detections are real and
      miss already (their gaps stay as MOT15 has them) — nor ``sim_noise`` / ``scenario``.

    ``mot_root`` goes to the mot part only, ``trackers`` to otb_tracker only."""
    defaults = {f.name: f.default for f in fields(EnvConfig)}
    changes: dict[str, Any] = {"source": part, "mix_weights": defaults["mix_weights"],
                               "trackers": cfg.trackers if part == "otb_tracker" else None,
                               "otb_speedup_max": 1 if part == "sim" else cfg.otb_speedup_max,
                               "mot_root": cfg.mot_root if part == "mot" else None}
    if part != "sim":
        changes.update({name: defaults[name] for name in SIM_ONLY})
    if part == "mot":
        changes.update({name: defaults[name] for name in DETECTION_ERRORS})
    return replace(cfg, **changes)
