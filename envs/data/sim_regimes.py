"""Non-stationary simulated tracks: the right filter parameters change within a track.

``scenario="nonstationary"`` (EnvConfig; source "sim" and the sim part of "mix", motion "cv") keeps the stationary
episode's drawn scenario (ψ, σ_w, σ_ξ, τ, box size: the same as the stationary episode of that noise seed) as
the first regime, and adds, from an independent generator ``default_rng((noise_seed, 4))``:

* **noise regimes** — ``noise_switches`` switch times (uniform, distinct, in [T // 10, T − T // 10), so that no
  regime is a sliver at either end); each new regime draws
  ψ (uniform in ``psi_range``) and σ_ξ (log-uniform in ``sigma_xi_range``) afresh — a detector that starts or
  stops drifting. The CMN runs on across a switch: v_n = ψ_k v_{n−1} + ξ_n, ξ_n ~ N(0, σ_ξ,k²) in regime k
  ([Shmaliy-CMN] eq. 2 with piecewise-constant ψ, σ_ξ);
* **manoeuvre bursts** — ``manoeuvres`` intervals of ``manoeuvre_frames`` frames (cut at the track's end) at
  uniform start frames, in which the centre's acceleration noise is σ_w × ``manoeuvre_gain`` (the box sizes
  are unaffected);
* **occlusion gaps** — ``gaps`` runs of ``gap_frames`` missing measurements (NaN rows of y; the truth is kept
  and scored), starting at uniform frames in [1, T − 1] (frame 0 is always measured).

The track itself (truth motion, CMN, gaps) is simulated from that generator too, so a nonstationary episode
shares its drawn scenario, not its noise, with the stationary one. The episode's ``scenario`` (revealed only
after the decision, as for stationary episodes) holds ``psi`` and ``sigma_xi`` averaged over frames
(frame-weighted mean ψ, rms σ_ξ; what the rules "with true σ" use), the first regime's ``sigma_w``, and the
whole schedule: ``regimes`` (list of {start, end, psi, sigma_xi}, frames [start, end)), ``manoeuvres`` and
``gaps`` (lists of [start, end)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.signal import lfilter

from bboxtune.envs.data.scenario_ranges import log_uniform
from bboxtune.envs.data.simulate import Scenario, Track, assemble, initial_conditions


@dataclass(frozen=True)
class RegimeRanges:
    """How often and how strongly a nonstationary track changes (inclusive (low, high) integer ranges, uniform)."""

    noise_switches: tuple[int, int] = (1, 3)  # ψ / σ_ξ regime switches per track
    manoeuvres: tuple[int, int] = (0, 3)  # manoeuvre bursts per track
    manoeuvre_frames: tuple[int, int] = (20, 100)  # frames per burst
    manoeuvre_gain: float = 10.0  # σ_w multiplier of the centre during a burst
    gaps: tuple[int, int] = (0, 2)  # occlusion gaps per track
    gap_frames: tuple[int, int] = (5, 30)  # missing frames per gap


REGIMES = RegimeRanges()


def _intervals(rng: np.random.Generator, count: tuple[int, int], length: tuple[int, int], T: int) -> list[list[int]]:
    """Sorted [start, end) intervals: ``count`` of them, starts uniform in [1, T − 1], lengths uniform, cut at T."""
    n = int(rng.integers(count[0], count[1], endpoint=True))
    starts = np.sort(rng.integers(1, T, size=n))
    lengths = rng.integers(length[0], length[1], endpoint=True, size=n)
    return [[int(s), int(min(s + k, T))] for s, k in zip(starts, lengths, strict=False)]


def simulate_nonstationary(base: Scenario, noise_seed: int, psi_range: tuple[float, float],
                           sigma_xi_range: tuple[float, float], ranges: RegimeRanges = REGIMES) -> tuple[Track, dict[str, Any]]:
    """The nonstationary box track of ``noise_seed`` around the drawn scenario ``base`` (ndim 4, motion "cv") and its
    true schedule (the episode's ``scenario`` dict, see the module docstring)."""
    if base.ndim != 4 or base.motion != "cv":
        raise ValueError(f"nonstationary tracks are box tracks with motion 'cv' (got ndim={base.ndim}, motion={base.motion!r})")
    rng = np.random.default_rng((noise_seed, 4))
    T = base.n_frames
    n_switch = min(int(rng.integers(ranges.noise_switches[0], ranges.noise_switches[1], endpoint=True)), T - 1)
    inner = np.arange(max(T // 10, 1), T - T // 10)
    n_switch = min(n_switch, inner.size)
    cuts = [0, *np.sort(rng.choice(inner, size=n_switch, replace=False)).tolist(), T]
    regimes = [{"start": 0, "end": cuts[1], "psi": base.psi, "sigma_xi": base.sigma_xi}]
    for start, end in zip(cuts[1:-1], cuts[2:], strict=False):
        regimes.append({"start": int(start), "end": int(end), "psi": float(rng.uniform(*psi_range)),
                        "sigma_xi": log_uniform(rng, sigma_xi_range)})
    manoeuvres = _intervals(rng, ranges.manoeuvres, ranges.manoeuvre_frames, T)
    gaps = _intervals(rng, ranges.gaps, ranges.gap_frames, T)

    p0, v0, sigma, sigma_xi, sizes0 = (a[0] for a in initial_conditions([base]))
    gain = np.ones((T - 1, 1))
    for start, end in manoeuvres:  # w_n moves frame n: frames [start, end) accelerate harder
        gain[max(start - 1, 0):end - 1] = ranges.manoeuvre_gain
    w = rng.standard_normal((T - 1, len(sigma))) * sigma
    w[:, :2] *= gain  # centre only (1)
    e = rng.standard_normal((T, base.M)) * (sigma_xi / base.sigma_xi)  # unit ξ on cx, cy; size ratio on w, h
    cmn = np.empty_like(e)
    v = e[0] * regimes[0]["sigma_xi"] / np.sqrt(1.0 - regimes[0]["psi"] ** 2)  # stationary start of regime 0
    cmn[0] = v
    for r in regimes:  # v_n = ψ_k v_{n−1} + ξ_n (2), carried across switches
        lo = max(r["start"], 1)
        if lo < r["end"]:
            cmn[lo:r["end"]], _ = lfilter([1.0], [1.0, -r["psi"]], e[lo:r["end"]] * r["sigma_xi"], axis=0,
                                          zi=r["psi"] * cmn[lo - 1][None])
    bounds = np.asarray(base.size_bounds, dtype=float)
    truth, state, y = assemble(p0[None], v0[None], w[None], base.tau, base.delta, cmn[None], sizes0, bounds)
    y = y[0]
    for start, end in gaps:
        y[start:end] = np.nan
    frames = np.array([r["end"] - r["start"] for r in regimes], dtype=float)
    schedule = {
        "psi": float(np.sum(frames * [r["psi"] for r in regimes]) / T),
        "sigma_w": base.sigma_w,
        "sigma_xi": float(np.sqrt(np.sum(frames * np.square([r["sigma_xi"] for r in regimes])) / T)),
        "scenario": "nonstationary", "regimes": regimes, "manoeuvres": manoeuvres, "gaps": gaps,
    }
    return Track(truth=truth[0], truth_state=state[0], y=y, tau=base.tau), schedule

