"""Configuration of the bboxtune environments: one frozen dataclass, keyword arguments of ``gym.make``."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import filters
from envs.actions import ACCEPTS, DEFAULT_TUNE

SOURCES = ("sim", "otb", "otb_tracker", "video")
SPLITS = ("train", "val", "test")
REWARDS = ("rmse", "iou_precision", "success_auc")


@dataclass(frozen=True)
class EnvConfig:
    """Every argument of ``bboxtune/FilterTune-v0`` and ``bboxtune/FilterRetune-v0`` (units in comments)."""

    source: str = "sim"  # "sim" | "otb" (GT + synthetic CMN) | "otb_tracker" (real tracker output) | "video"
    backend: str = "ufir_cmn"  # any name in filters.NAMES
    reward: str = "rmse"  # "rmse": log(RMSE_rule / RMSE); "iou_precision" / "success_auc": difference to the rule
    tune: tuple[str, ...] | None = None  # parameters the agent sets; None -> envs.actions.DEFAULT_TUNE[backend]
    track_length: int = 500  # frames per simulated track
    # sim scenario distribution ((low, high); log-uniform for σ, uniform otherwise)
    psi_range: tuple[float, float] = (0.0, 0.95)
    sigma_w_range: tuple[float, float] = (1.0, 100.0)  # px/s², acceleration noise std of cx, cy
    sigma_xi_range: tuple[float, float] = (0.5, 10.0)  # px, std of the white noise ξ driving the CMN
    tau_range: tuple[float, float] = (1 / 30, 0.1)  # s, frame interval
    box_size_range: tuple[float, float] = (20.0, 200.0)  # px, initial w and h
    # OTB sources
    otb_root: str | None = None  # folder of the OTB data; None -> $OTB_ROOT
    split: str = "train"  # "train" | "val" | "test": which sequences episodes are drawn from
    tracker: str = "SiamFC"  # source "otb_tracker": whose output is the measurement
    otb_tau: float = 1 / 30  # s, OTB frame interval (30 fps)
    cmn_rel_range: tuple[float, float] = (0.01, 0.1)  # source "otb": σ_ξ relative to the box size, log-uniform
    otb_sigma_v_rel: float = 0.03  # nominal σ_v relative to the measured box scale (OTB sources)
    otb_sigma_w_rel: float = 3.0  # 1/s², nominal σ_w relative to the measured box scale (OTB sources)
    # source "video": synthetic videos measured by a real detector (envs.video.source.VideoSource)
    detector: str = "template"  # one of envs.video.detectors.DETECTORS
    video_pool: int = 64  # distinct videos per split
    video_cache: str | None = None  # folder caching rendered + detected videos; None: memory only
    video_size: tuple[int, int] = (320, 240)  # px, frame width and height
    video_sigma_v_rel: float | None = None  # nominal σ_v / box scale; None: the detector's calibrated value
    video_sigma_w_rel: float | None = None  # 1/s², nominal σ_w / box scale; None: calibrated value
    # action mapping
    horizon_max: int = 400  # frames, largest FIR horizon the agent can choose
    sigma_decades: float = 1.5  # σ scales span nominal · 10^[-D, D]
    nominal_psi: float = 0.0  # ψ the fixed rule assumes (the white-noise rule of the literature)
    # FilterRetune-v0
    window: int = 50  # frames per re-tuning step
    history: int = 100  # frames of past measurements the re-tuning observation summarises

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise ValueError(f"source={self.source!r}; allowed: {SOURCES}")
        if self.backend not in filters.NAMES:
            raise ValueError(f"backend={self.backend!r}; allowed: {filters.NAMES}")
        if self.reward not in REWARDS:
            raise ValueError(f"reward={self.reward!r}; allowed: {REWARDS}")
        if self.split not in SPLITS:
            raise ValueError(f"split={self.split!r}; allowed: {SPLITS}")
        tune = DEFAULT_TUNE[self.backend] if self.tune is None else tuple(self.tune)
        bad = [p for p in tune if p not in ACCEPTS[self.backend]]
        if bad or not tune or len(set(tune)) != len(tune):
            raise ValueError(f"tune={tune!r} for backend {self.backend!r}; allowed: distinct names from {ACCEPTS[self.backend]}")
        object.__setattr__(self, "tune", tune)
        for name in ("track_length", "window", "history"):
            if int(getattr(self, name)) < 8:
                raise ValueError(f"{name}={getattr(self, name)!r}; allowed: integers >= 8")
        for name in ("psi_range", "sigma_w_range", "sigma_xi_range", "tau_range", "box_size_range", "cmn_rel_range"):
            lo, hi = getattr(self, name)
            if not (0 <= lo <= hi) or (name != "psi_range" and lo <= 0):
                raise ValueError(f"{name}={(lo, hi)!r}; allowed: 0 < low <= high (0 <= low for psi)")
        if self.psi_range[1] >= 1 or not 0 <= self.nominal_psi < 1:
            raise ValueError(f"psi_range={self.psi_range!r}, nominal_psi={self.nominal_psi!r}; allowed within [0, 1)")
        if self.source == "video":
            from envs.video.source import VideoSettings

            VideoSettings.from_config(self)  # validates the video fields
        if self.horizon_max < 2 or self.horizon_max > 10_000:
            raise ValueError(f"horizon_max={self.horizon_max!r}; allowed: 2 <= horizon_max <= 10000")

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> EnvConfig:
        """Build from ``gym.make`` keyword arguments; an unknown key raises ``TypeError`` naming it."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(kwargs) - known)
        if unknown:
            raise TypeError(f"unknown env argument(s) {unknown}; allowed: {sorted(known)}")
        for key in ("tune", "video_size", "psi_range", "sigma_w_range", "sigma_xi_range", "tau_range", "box_size_range", "cmn_rel_range"):
            if key in kwargs and kwargs[key] is not None:
                kwargs[key] = tuple(kwargs[key])
        return cls(**kwargs)


