"""Distributions over simulation set-ups: :class:`ScenarioRanges`, a range for each :class:`Scenario` field, from
which the sim source draws every episode's scenario (:mod:`bboxtune.envs.episodes.sources`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from bboxtune.envs.data.sim_motion import OTB_MOTION
from bboxtune.envs.data.simulate import Scenario


def _uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(bounds[0], bounds[1])) if bounds[1] > bounds[0] else float(bounds[0])


def log_uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(math.exp(_uniform(rng, (math.log(bounds[0]), math.log(bounds[1])))))


@dataclass(frozen=True)
class ScenarioRanges:
    """A distribution over :class:`Scenario`: each field is an inclusive (low, high) range; low == high fixes it.

    ψ, τ and δ are uniform; σ_w, σ_ξ and the initial box sizes are log-uniform; ``n_frames`` is a uniform
    integer. The default duration is at most 1000 × 0.05 s = 50 s, which keeps log-size growth moderate."""

    psi: tuple[float, float] = (0.0, 0.95)  # uniform, 0 <= ψ < 1
    sigma_w: tuple[float, float] = (1.0, 100.0)  # px/s², log-uniform
    sigma_xi: tuple[float, float] = (0.5, 10.0)  # px, log-uniform
    tau: tuple[float, float] = (1 / 30, 0.05)  # s, uniform (30 to 20 frames per second)
    n_frames: tuple[int, int] = (200, 1000)  # frames, uniform integer
    delta: tuple[float, float] = (0.0, 0.0)  # s, uniform
    size: tuple[float, float] = (20.0, 200.0)  # px, initial w and h (independent, log-uniform), ndim 4
    ndim: int = 4  # 1, 2 or 4 (see Scenario)
    size_bounds: tuple[float, float] = (4.0, 1000.0)  # px, where true w and h are reflected (Scenario.size_bounds)
    motion: str = "cv"  # Scenario.motion; "otb" draws velocity_rms and size_rw (bboxtune.envs.data.sim_motion), σ_w is unused

    def __post_init__(self) -> None:
        for name in ("psi", "sigma_w", "sigma_xi", "tau", "n_frames", "delta", "size"):
            low, high = getattr(self, name)
            if not (math.isfinite(low) and math.isfinite(high) and low <= high):
                raise ValueError(f"{name}={(low, high)!r} must be a finite range with low <= high")
        for name in ("sigma_w", "sigma_xi", "size"):
            if getattr(self, name)[0] <= 0:
                raise ValueError(f"{name}={getattr(self, name)!r}: log-uniform ranges need low > 0")
        x0 = (0.0, 0.0, *self.size, 0.0, 0.0, 0.0, 0.0) if self.ndim == 4 else None  # both initial-size ends in bounds
        Scenario(psi=self.psi[1], tau=self.tau[0], delta=self.delta[0], ndim=self.ndim, size_bounds=self.size_bounds, x0=x0,
                 motion=self.motion)
        Scenario(psi=self.psi[0], tau=self.tau[1], delta=self.delta[1], n_frames=int(self.n_frames[0]))

    @cached_property
    def _draw_plan(self) -> tuple[list[tuple[float, float, bool]], int]:
        """(low, high, log-uniform) of the initial sizes, ψ, σ_w, σ_ξ and τ in draw order (logs of log-uniform
        ranges), and how many of them are not a point."""
        fields = [*[(self.size, True)] * (2 if self.ndim == 4 else 0), (self.psi, False), (self.sigma_w, True),
                  (self.sigma_xi, True), (self.tau, False)]
        bounds: list[tuple[float, float, bool]] = [(math.log(lo), math.log(hi), log) if log else (lo, hi, log)
                                                   for (lo, hi), log in fields]
        return bounds, sum(hi > lo for lo, hi, _ in bounds)

    def sample(self, rng: np.random.Generator) -> Scenario:
        """Draw one scenario (the x0 of a box puts a box of random size at rest at (320, 240)); "otb" motion
        draws its levels after the other fields, so the "cv" fields of a seed are the same under both.

        The uniforms of the initial sizes, ψ, σ_w, σ_ξ and τ — one for each whose range is not a point, in that
        order — come from one ``rng.random`` call: the same numbers, and the same values, as a ``rng.uniform(low,
        high)`` each (low + (high − low)·u). A point range of ``n_frames`` draws nothing, as ``rng.integers`` of
        one value does not."""
        fields, n_random = self._draw_plan
        u = iter(rng.random(n_random).tolist())
        drawn = [lo + (hi - lo) * next(u) if hi > lo else float(lo) for lo, hi, _ in fields]  # in field order
        *size, psi, sigma_w, sigma_xi, tau = [math.exp(v) if log else v for v, (_, _, log) in zip(drawn, fields, strict=True)]
        low, high = self.n_frames
        scenario = Scenario(
            psi=psi, sigma_w=sigma_w, sigma_xi=sigma_xi, tau=tau,
            n_frames=int(rng.integers(low, high, endpoint=True)) if high > low else int(low),
            ndim=self.ndim,
            delta=_uniform(rng, self.delta),
            x0=(320.0, 240.0, *size, 0.0, 0.0, 0.0, 0.0) if size else None,
            size_bounds=self.size_bounds,
        )
        if self.motion == "cv":
            return scenario
        velocity_rms, size_rw = OTB_MOTION.sample_levels(rng)
        return replace(scenario, motion=self.motion, velocity_rms=velocity_rms, size_rw=size_rw)
