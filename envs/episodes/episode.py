"""An episode (one track: measured boxes, truth, the rule's nominal parameters) and the interface of the sources
that draw them (:mod:`bboxtune.envs.episodes.sources` has the simulator, OTB and mixed sources and ``make_source``;
:mod:`bboxtune.envs.episodes.video_source` the synthetic-video source)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bboxtune.envs.episodes.actions import Nominal
from bboxtune.envs.episodes.config import EnvConfig


@dataclass(frozen=True)
class Episode:
    """One track to be filtered: boxes are (cx, cy, w, h) in px."""

    truth: np.ndarray  # (T, 4) true boxes; NaN rows: no ground truth (excluded from scores)
    y: np.ndarray  # (T, 4) measured boxes; NaN rows: missing detection
    tau: float  # s, frame interval the filters assume
    nominal: Nominal  # the fixed rule's parameters for this episode (from measurements / config only)
    meta: dict[str, Any] = field(default_factory=dict)  # what identifies it: sequence, noise_seed, tau, …
    scenario: dict[str, Any] = field(default_factory=dict)  # the true ψ, σ that made the noise (hidden until the step)


def rule_nominal(cfg: EnvConfig, sigma_v: float, sigma_w: float, tau: float) -> Nominal:
    """The fixed rule's parameters for nominal σ_v, σ_w (px, px/s²) at frame interval ``tau`` (s): N = N_opt
    within [K, ``cfg.horizon_max``], ψ = ``cfg.nominal_psi``."""
    return Nominal.of_rule(sigma_v, sigma_w, tau, cfg.nominal_psi, cfg.horizon_max)


class Source:
    """What the environments draw episodes from: ``draw(sequence, noise_seed)`` (subclasses) and
    ``draw_many(noise_seeds)``, the unpinned episodes of those seeds; ``block`` is how many of them
    FilterTune-v0 draws and prepares at once; ``n_frames`` the length of every episode when it is fixed;
    ``trackers`` those a ``tracker`` argument of ``draw`` may pin (none: the env refuses the option)."""

    block = 1
    n_frames: int | None = None
    min_frames = 2
    trackers: tuple[str, ...] = ()

    def require_frames(self, n: int, why: str) -> None:
        """Draw only episodes of at least ``n`` frames (``why``: what needs them, for the error message).
        A fixed ``n_frames`` below ``n`` raises ``ValueError`` naming ``track_length``."""
        if self.n_frames is not None and self.n_frames < n:
            raise ValueError(f"track_length={self.n_frames} is too short: {why} needs at least {n} frames")
        self.min_frames = n

    def max_frames(self) -> int:
        """The most frames an episode of this source can have: ``n_frames`` where it is fixed (the sources of
        varying length override this); what memory estimates multiply by (:mod:`bboxtune.envs.data.memory`)."""
        if self.n_frames is None:
            raise NotImplementedError(f"{type(self).__name__} draws episodes of varying length: it must override max_frames")
        return self.n_frames

    def draw(self, sequence: str | None, noise_seed: int) -> Episode:
        raise NotImplementedError

    def draw_many(self, noise_seeds: list[int]) -> list[Episode]:
        """``[draw(None, s) for s in noise_seeds]`` (sources with a batched form override it)."""
        return [self.draw(None, s) for s in noise_seeds]
