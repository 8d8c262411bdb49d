"""Simulated tracks: constant-velocity truth plus Gauss–Markov coloured measurement noise (CMN).

Model ([Shmaliy-CMN] eqs. 1–3, backward Euler; per coordinate, every coordinate independent):

    x_n = F(τ+δ) x_{n−1} + B(τ) w_n,  F(t) = [[1, t], [0, 1]],  B(t) = [t²/2, t]ᵀ,  w_n ~ N(0, σ_w²)  (1)
    v_n = ψ v_{n−1} + ξ_n,           ξ_n ~ N(0, σ_ξ²),  v_0 ~ N(0, σ_ξ²/(1 − ψ²)) (stationary start)  (2)
    y_n = H x_n + v_n,               H = [1, 0]                                                     (3)

The truth may use F(τ + δ) while the filters assume F(τ): [Mo-FIR]'s sampling-time error δ enters the
transition matrix only (its eqs. 1 and 4: A has dt + δ, the process noise is unchanged), so B stays B(τ).
Frame 0 holds the initial state ``x0`` exactly (P0 = 0, as [Shmaliy-CMN]).

Box tracks (``ndim = 4``, coordinates cx, cy, w, h in px): cx and cy follow (1) with σ_w. The sizes follow the
same model in log space, ℓ = log(w / w_0) with ℓ_0 = 0, ℓ̇_0 = ẇ_0 / w_0 and acceleration noise
``sigma_w_log_size`` (1/s²), so w = w_0 exp(ℓ) stays positive and changes slowly (the std of ℓ after t seconds is
about σ t^1.5/√3: 0.14 after 25 s at the default 0.002). The true size velocity is ẇ = w ℓ̇.

Size bounds: a free log-size path drifts without limit (its std grows as t^1.5; unbounded, 10,000 frames at
τ = 0.1 s gave boxes of 1e13 px), so the sizes are *reflected* at ``size_bounds`` (default 4 to 1000 px;
OTB-100's ground-truth boxes span 7 to 396 px): ℓ is folded into [log(lo/w_0), log(hi/w_0)] like a ball
bouncing between two walls — the reflected path is the mirror image of the free one, and its velocity ℓ̇
changes sign at each bounce — so w always lies in [lo, hi]. A track that never reaches a bound is bit for bit
the free one (every default 500-frame env track: their sizes span 13.5 to 335 px over 100,000 episodes).

The CMN (2) is added to all four coordinates, with σ_ξ on cx, cy and ``size_noise_ratio``·σ_ξ on w, h;
measured sizes can therefore be <= 0 when the noise is large compared with the box (the metrics score such
boxes as empty).

Motion models (``Scenario.motion``): "cv" (default) is the model above; "otb" (box tracks only) replaces the
truth's motion by the one fitted to OTB-100's ground truth — scale-relative centre velocity with manoeuvres and
a log-size random walk (:mod:`bboxtune.envs.data.sim_motion`, docs/otb_motion.md) — with the same CMN (2)–(3); ``sigma_w`` and
``sigma_w_log_size`` are then unused and ``velocity_rms``, ``size_rw`` set the episode's motion level.

Everything is drawn from the ``numpy.random.Generator`` passed in, so an episode is reproducible from its seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from scipy.signal import lfilter

from bboxtune.envs.data import simulate_kernels
from bboxtune.envs.data.sim_motion import OTB_MOTION, draw_extra, otb_paths, reflect
from bboxtune.filters import jit
from bboxtune.filters.threads import in_threads

MOTIONS = ("cv", "otb")  # truth motion models: constant velocity ([Shmaliy-CMN] eq. 1) or fitted to OTB-100
_NDIMS = (1, 2, 4)  # scalar two-state, centroid (cx, cy), box (cx, cy, w, h)
_DEFAULT_BOX_X0 = (320.0, 240.0, 64.0, 48.0, 0.0, 0.0, 0.0, 0.0)  # px, px/s: a 64×48 box at a VGA centre


class Track(NamedTuple):
    """One episode's data (or a batch, with a leading axis B). NaN marks missing truth / measurements."""

    truth: np.ndarray  # (T, M) true measured quantities: positions; boxes (cx, cy, w, h) px
    truth_state: np.ndarray  # (T, K) true state in the filters' layout [p_1 … p_M, v_1 … v_M]
    y: np.ndarray  # (T, M) measurements, same coordinates as ``truth``
    tau: float  # s, sampling interval the filters should assume


@dataclass(frozen=True)
class Scenario:
    """One simulation set-up. Units in the comments; validated on construction."""

    psi: float = 0.0  # CMN colouredness ψ, 0 <= ψ < 1 (0 = white noise)
    sigma_w: float = 1.0  # px/s² (m/s² in the papers): acceleration noise std of positions
    sigma_xi: float = 1.0  # px (m): std of the white noise ξ driving the CMN on positions
    tau: float = 0.05  # s: sampling interval the filters assume
    n_frames: int = 500  # T, frames per track (>= 2)
    ndim: int = 4  # 1: scalar two-state [p, v]; 2: centroid (cx, cy); 4: box (cx, cy, w, h)
    delta: float = 0.0  # s: sampling-time error; the truth evolves with τ + δ ([Mo-FIR]), τ + δ > 0
    x0: tuple[float, ...] | None = None  # (2·ndim,) initial true state [p…, v…]; None: zeros, or a 64×48 box
    sigma_w_log_size: float = 0.002  # 1/s²: acceleration noise std of log w and log h (ndim 4)
    size_noise_ratio: float = 0.5  # σ_ξ of the w, h measurements as a fraction of sigma_xi (ndim 4)
    size_bounds: tuple[float, float] = (4.0, 1000.0)  # px: true w and h are reflected at these bounds (ndim 4)
    motion: str = "cv"  # "cv": model (1); "otb": bboxtune.envs.data.sim_motion's fitted OTB motion (ndim 4 only)
    velocity_rms: float = 1.0  # box scales/s: rms centre velocity σ_r ("otb")
    size_rw: float = 0.1  # 1/√s: random-walk std σ_ℓ of log w and log h ("otb")

    def __post_init__(self) -> None:
        if self.motion not in MOTIONS or (self.motion == "otb" and self.ndim != 4):
            raise ValueError(f"motion={self.motion!r} with ndim={self.ndim!r}: allowed {MOTIONS}, 'otb' with ndim 4 only")
        for name in ("velocity_rms", "size_rw"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name}={getattr(self, name)!r} is out of range: allowed finite values > 0")
        if not (math.isfinite(self.psi) and 0.0 <= self.psi < 1.0):
            raise ValueError(f"psi={self.psi!r} is out of range: allowed 0 <= psi < 1")
        for name in ("sigma_w", "sigma_xi", "tau", "sigma_w_log_size", "size_noise_ratio"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r} is out of range: allowed finite values > 0")
        if self.ndim not in _NDIMS:
            raise ValueError(f"ndim={self.ndim!r} is out of range: allowed {_NDIMS}")
        if not isinstance(self.n_frames, (int, np.integer)) or self.n_frames < 2:
            raise ValueError(f"n_frames={self.n_frames!r} is out of range: allowed integers >= 2")
        if not (math.isfinite(self.delta) and self.tau + self.delta > 0):
            raise ValueError(f"delta={self.delta!r} is out of range: allowed finite with tau + delta > 0")
        initial_state = self.initial_state
        x0 = initial_state.tolist()  # Python floats: faster checks of a few values than numpy's
        if initial_state.shape != (self.K,) or not all(math.isfinite(v) for v in x0):
            raise ValueError(f"x0={self.x0!r} must be {self.K} finite values [positions…, velocities…]")
        lo, hi = self.size_bounds
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
            raise ValueError(f"size_bounds={self.size_bounds!r} is out of range: allowed finite 0 < low < high (px)")
        if self.ndim == 4 and not (lo <= x0[2] <= hi and lo <= x0[3] <= hi):
            raise ValueError(f"x0={self.x0!r}: box sizes x0[2], x0[3] must lie within size_bounds={self.size_bounds!r} px")

    @property
    def M(self) -> int:
        """Measurement size (= ndim)."""
        return self.ndim

    @property
    def K(self) -> int:
        """State size (= 2·ndim)."""
        return 2 * self.ndim

    @property
    def initial_state(self) -> np.ndarray:
        """x0 as a (K,) array, with the documented default when ``x0`` is None."""
        if self.x0 is not None:
            return np.asarray(self.x0, dtype=float)
        return np.array(_DEFAULT_BOX_X0) if self.ndim == 4 else np.zeros(self.K)


def _integrate(p0: np.ndarray, v0: np.ndarray, w: np.ndarray, tau: float | np.ndarray,
               delta: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of x_n = F(τ + δ) x_{n−1} + B(τ) w_n (1) for independent coordinates, by
    cumsums from the scaled acceleration noise ``w`` (B, T − 1, C) and the start ``p0``, ``v0`` (B, C); ``tau``,
    ``delta`` scalars or (B, 1, 1) arrays (one per track). Every track's arithmetic is the same whatever the
    batch. Computed with time as the last (contiguous) axis, where cumulative sums are fast; returns two
    (B, T, C) arrays with frame 0 = (p0, v0)."""
    w = np.ascontiguousarray(w.transpose(0, 2, 1))  # (B, C, T − 1)
    v = np.concatenate([v0[:, :, None], v0[:, :, None] + tau * np.cumsum(w, axis=2)], axis=2)  # v_n = v_{n−1} + τ w_n (1)
    steps = (tau + delta) * v[:, :, :-1] + 0.5 * (tau * tau) * w  # p_n − p_{n−1} = (τ + δ) v_{n−1} + τ²/2 w_n (1)
    p = np.concatenate([p0[:, :, None], p0[:, :, None] + np.cumsum(steps, axis=2)], axis=2)
    return p.transpose(0, 2, 1), v.transpose(0, 2, 1)


def gauss_markov(psi: float, sigma_xi: np.ndarray, shape: tuple[int, int, int], rng: np.random.Generator) -> np.ndarray:
    """Stationary CMN (2) shaped (B, T, C) with per-coordinate ξ std ``sigma_xi`` (C,) along axis 1."""
    return _colour(rng.standard_normal(shape) * np.asarray(sigma_xi, dtype=float), psi)


def _colour(e: np.ndarray, psi: float) -> np.ndarray:
    """(2) in place on the scaled white noise ``e`` (B, T, C) → the CMN (B, T, C)."""
    return _colour_each(e, [psi] * len(e))


def _colour_each(e: np.ndarray, psis: list[float]) -> np.ndarray:
    """(2) on the scaled white noise ``e`` (B, T, C) of B tracks, track b with ψ = ``psis[b]`` (in place, where
    possible) → the CMN (B, T, C)."""
    start_std = np.array([math.sqrt(1.0 - psi**2) for psi in psis])  # v_0 ~ N(0, σ_ξ²/(1 − ψ²)), the stationary law
    if jit.enabled():
        simulate_kernels.colour(e, np.asarray(psis, dtype=float), start_std)
        return e
    e[:, 0] /= start_std[:, None]
    for b, psi in enumerate(psis):
        if psi != 0.0:
            e[b] = lfilter([1.0], [1.0, -psi], e[b], axis=0)  # v_n = ψ v_{n−1} + ξ_n (2)
    return e


def simulate(scenario: Scenario, rng: np.random.Generator, n_tracks: int | None = None) -> Track:
    """Draw one track (``n_tracks=None``: arrays (T, ·)) or a batch of independent tracks (arrays (B, T, ·)).

    >>> tr = simulate(PRESETS["seed000_two_state"], np.random.default_rng(0))
    >>> tr.truth.shape, tr.truth_state.shape, tr.y.shape, tr.tau
    ((2000, 1), (2000, 2), (2000, 1), 0.05)
    """
    if n_tracks is not None and (not isinstance(n_tracks, (int, np.integer)) or n_tracks < 1):
        raise ValueError(f"n_tracks={n_tracks!r} is out of range: allowed None or an integer >= 1")
    s, B, T = scenario, 1 if n_tracks is None else int(n_tracks), scenario.n_frames
    p0, v0, sigma, sigma_xi, sizes0 = (a[0] for a in initial_conditions([s]))
    w = rng.standard_normal((B, T - 1, len(sigma)))
    e = rng.standard_normal((B, T, s.M)) * sigma_xi
    if s.motion == "otb":
        normals, uniforms = rng.standard_normal((B, T + 1, 2)), rng.random((B, T, 2))
        truth, state, y = _assemble_otb([s] * B, w, normals, uniforms, _colour(e, s.psi))
    else:
        truth, state, y = assemble(np.tile(p0, (B, 1)), np.tile(v0, (B, 1)), w * sigma, s.tau, s.delta, _colour(e, s.psi),
                                    sizes0, np.asarray(s.size_bounds, dtype=float))
    if n_tracks is None:
        return Track(truth=truth[0], truth_state=state[0], y=y[0], tau=s.tau)
    return Track(truth=truth, truth_state=state, y=y, tau=s.tau)


def simulate_each(scenarios: list[Scenario], rngs: list[np.random.Generator]) -> list[Track]:
    """One track per (scenario, generator) pair, each equal to ``simulate(scenario, rng)``, in one
    vectorised pass (the scenarios must share ``n_frames``, ``ndim`` and ``motion``; the random draws stay per
    generator; a large batch is split over threads, each on its own tracks and generators: the same numbers)."""
    s0 = scenarios[0]
    if len(rngs) != len(scenarios) or any((s.n_frames, s.ndim, s.motion) != (s0.n_frames, s0.ndim, s0.motion) for s in scenarios):
        raise ValueError("simulate_each needs one generator per scenario and scenarios of equal n_frames, ndim and motion")
    starts = initial_conditions(scenarios)

    def simulate_part(part: slice) -> list[Track]:  # in a thread of its own (numpy's draws, the kernels: no GIL)
        return _simulate_rows(scenarios[part], rngs[part], tuple(a[part] for a in starts))

    return [track for tracks in in_threads(simulate_part, len(scenarios), s0.n_frames * s0.M) for track in tracks]


def _simulate_rows(scenarios: list[Scenario], rngs: list[np.random.Generator], starts: tuple[np.ndarray, ...]
                   ) -> list[Track]:
    """:func:`simulate_each` of one part of its batch, with the scenarios' :func:`initial_conditions` ``starts``."""
    s0 = scenarios[0]
    p0, v0, sigma, sigma_xi, sizes0 = starts
    T, C, B = s0.n_frames, sigma.shape[1], len(scenarios)
    w, e = np.empty((B, T - 1, C)), np.empty((B, T, s0.M))
    normals, uniforms = np.empty((B, T + 1, 2)), np.empty((B, T, 2))
    for i, rng in enumerate(rngs):  # in simulate's order: w, ξ, extras (filled in place: the same numbers)
        rng.standard_normal(out=w[i])
        rng.standard_normal(out=e[i])
        if s0.motion == "otb":
            normals[i], uniforms[i] = draw_extra(rng, T)
    if s0.motion == "cv":
        w *= sigma[:, None]
    e *= sigma_xi[:, None]
    cmn = _colour_each(e, [s.psi for s in scenarios])
    if s0.motion == "otb":
        truth, state, y = _assemble_otb(scenarios, w, normals, uniforms, cmn)
        return [Track(truth=truth[i], truth_state=state[i], y=y[i], tau=s.tau) for i, s in enumerate(scenarios)]
    column = lambda name: np.array([getattr(s, name) for s in scenarios])[:, None, None]  # noqa: E731
    bounds = np.array([s.size_bounds for s in scenarios])[:, None]  # (B, 1, 2): low, high per track
    truth, state, y = assemble(p0, v0, w, column("tau"), column("delta"), cmn, sizes0[:, None], bounds)
    return [Track(truth=truth[i], truth_state=state[i], y=y[i], tau=s.tau) for i, s in enumerate(scenarios)]


def initial_conditions(scenarios: list[Scenario]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per scenario (one row each; all of one ndim): the initial positions and velocities of the simulated
    coordinates (box sizes in log space) (B, C), their acceleration noise std (B, C), the ξ std of each measured
    coordinate (B, M) and the initial box size (w_0, h_0) (B, 2) (B, 0 unless ndim = 4)."""
    M, B = scenarios[0].M, len(scenarios)
    default = _DEFAULT_BOX_X0 if M == 4 else (0.0,) * (2 * M)
    x0 = np.array([default if s.x0 is None else s.x0 for s in scenarios], dtype=float)
    sigma_w, sigma_xi = np.array([s.sigma_w for s in scenarios]), np.array([s.sigma_xi for s in scenarios])[:, None]
    if M == 4:
        sizes0, ones = x0[:, 2:4], np.ones(B)
        p0 = np.concatenate([x0[:, :2], np.zeros((B, 2))], axis=1)  # log sizes ℓ start at 0
        v0 = np.concatenate([x0[:, 4:6], x0[:, 6:8] / sizes0], axis=1)  # ℓ̇_0 = ẇ_0 / w_0
        log_size = np.array([s.sigma_w_log_size for s in scenarios])
        ratio = np.array([s.size_noise_ratio for s in scenarios])
        return (p0, v0, np.stack([sigma_w, sigma_w, log_size, log_size], axis=1),
                sigma_xi * np.stack([ones, ones, ratio, ratio], axis=1), sizes0)
    return x0[:, :M], x0[:, M:], np.repeat(sigma_w[:, None], M, axis=1), np.repeat(sigma_xi, M, axis=1), np.empty((B, 0))


def assemble(p0: np.ndarray, v0: np.ndarray, w: np.ndarray, tau: float | np.ndarray, delta: float | np.ndarray,
              cmn: np.ndarray, sizes0: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth (B, T, M), true state (B, T, K) and measurements (B, T, M) from the drawn noise (``sizes0``: the
    initial (w_0, h_0) of a box track, (2,) or (B, 1, 2), and ``bounds`` its size bounds (low, high) px, (2,)
    or (B, 1, 2); empty for ndim 1 and 2). The compiled kernel or :func:`assemble_numpy` (equal bit for bit)."""
    if not jit.enabled():
        return assemble_numpy(p0, v0, w, tau, delta, cmn, sizes0, bounds)
    B, T, C = w.shape[0], w.shape[1] + 1, w.shape[2]
    per_track = lambda x: _rows(np.asarray(x, dtype=float).reshape(-1), B)  # noqa: E731
    if sizes0.size:
        sizes0, bounds = _rows(sizes0.reshape(-1, 2), B), _rows(bounds.reshape(-1, 2), B)
        low, high = np.log(bounds[:, :1] / sizes0), np.log(bounds[:, 1:] / sizes0)  # bounds of ℓ
    else:
        low = high = sizes0 = np.empty((B, 0))
    state = np.empty((B, T, 2 * C))
    simulate_kernels.integrate(np.ascontiguousarray(p0, dtype=float), np.ascontiguousarray(v0, dtype=float),
                               np.ascontiguousarray(w, dtype=float), per_track(tau), per_track(delta), low, high, state)
    growth = np.exp(state[..., 2:4]) if sizes0.size else np.empty((B, T, 0))  # w = w_0 exp(ℓ)
    truth, y = simulate_kernels.measure(state, growth, np.ascontiguousarray(sizes0), np.ascontiguousarray(cmn, dtype=float))
    return truth, state, y


def _rows(a: np.ndarray, B: int) -> np.ndarray:
    """``a`` (1, …) or (B, …) as a C-contiguous array of B rows (the one row repeated, or ``a`` itself)."""
    return np.ascontiguousarray(a if len(a) == B else np.broadcast_to(a, (B, *a.shape[1:])))


def assemble_numpy(p0: np.ndarray, v0: np.ndarray, w: np.ndarray, tau: float | np.ndarray, delta: float | np.ndarray,
                   cmn: np.ndarray, sizes0: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`assemble` in numpy (the reference of the kernel)."""
    p, v = _integrate(p0, v0, w, tau, delta)
    if sizes0.size:
        low, high = np.log(bounds[..., :1] / sizes0), np.log(bounds[..., 1:] / sizes0)  # bounds of ℓ
        ell, rate = reflect(p[..., 2:], v[..., 2:], low, high)
        sizes = sizes0 * np.exp(ell)  # w = w_0 exp(ℓ)
        p = np.concatenate([p[..., :2], sizes], axis=-1)
        v = np.concatenate([v[..., :2], sizes * rate], axis=-1)  # ẇ = w ℓ̇
    y = p + cmn  # (3)
    return p, np.concatenate([p, v], axis=-1), y


def _assemble_otb(scenarios: list[Scenario], eps: np.ndarray, normals: np.ndarray, uniforms: np.ndarray,
                  cmn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth, true state and measurements of "otb" box tracks (one scenario per track) from the drawn noise."""
    x0 = np.array([s.initial_state[:4] for s in scenarios])
    step = np.array([s.tau + s.delta for s in scenarios])
    levels = np.array([(s.velocity_rms, s.size_rw) for s in scenarios])
    bounds = np.array([s.size_bounds for s in scenarios])
    p, v = otb_paths(eps, normals, uniforms, x0, step, levels, bounds, OTB_MOTION)
    y = p + cmn  # (3)
    return p, np.concatenate([p, v], axis=-1), y


def _box_x0(x: float, y: float, w: float, h: float) -> tuple[float, ...]:
    """Initial box state at rest from an OTB first box (x, y, w, h)."""
    return (x + w / 2, y + h / 2, w, h, 0.0, 0.0, 0.0, 0.0)


_SEED000_TWO_STATE = Scenario(psi=0.0, sigma_w=50.0, sigma_xi=4.0, tau=0.05, n_frames=2000, ndim=1, x0=(1.0, 1.0))
_SEED001_SIM = Scenario(psi=0.0, sigma_w=4.0, sigma_xi=3.0, tau=0.05, n_frames=1000, ndim=4)
_SEED004 = Scenario(psi=0.0, sigma_w=0.2, sigma_xi=10.0, tau=1.0, n_frames=500, ndim=2)

PRESETS: dict[str, Scenario] = {
    # [Shmaliy-CMN] §II.D: two-state track, σ_w = 50 m/s², σ_ξ = 4 m, τ = 0.05 s, 2000 points, x0 = [1, 1]ᵀ, P0 = 0.
    # The paper sweeps ψ over [0, 0.95]; use dataclasses.replace(PRESETS[...], psi=...).
    "seed000_two_state": _SEED000_TWO_STATE,
    # [Shmaliy-CMN] §III (Car4): τ = 0.05 s, σ_w = 3, σ_ξ = 2, ψ ≈ 0.9, as a box track starting from Car4's first
    # box (70, 51, 107, 87) for Car4's 659 frames.
    "seed000_car4": Scenario(psi=0.9, sigma_w=3.0, sigma_xi=2.0, tau=0.05, n_frames=659, ndim=4,
                             x0=_box_x0(70, 51, 107, 87)),
    # [PaleRamon-BBox] §9.1 simulated data 1 (σ_w = 4, σ_ξ = 3, 1000 points, T = 0.05 s; N_opt = 15) and 2 (σ_w = 45,
    # σ_ξ = 25; N_opt = 10). ψ, x0 and the box sizes are lost in our text copy of the paper: white noise
    # (ψ = 0) and the default 64×48 box are our choice.
    "seed001_sim1": _SEED001_SIM,
    "seed001_sim2": replace(_SEED001_SIM, sigma_w=45.0, sigma_xi=25.0),
    # [PaleRamon-BBox] §9.2 "SUV" tuning: σ_w = 10, σ_ξ = 5, T = 0.05 s (N_opt = √(12·5/(0.05²·10)) = 49, as reported),
    # as a box track from the OTB Suv first box (142, 125, 91, 40) for its 945 frames; ψ = 0 (not recoverable).
    "seed001_suv": Scenario(psi=0.0, sigma_w=10.0, sigma_xi=5.0, tau=0.05, n_frames=945, ndim=4,
                            x0=_box_x0(142, 125, 91, 40)),
    # [Mo-FIR] Table I: 2-D centroid (x, y) CV track in pixels with time in frames (τ = 1) and sampling-time
    # error δ = 0 or 10 in F. The paper gives no q, r or length: white noise σ_ξ = 10 px, σ_w = 0.2 px/frame²
    # (a KF then has RMSE ≈ 6 px at δ = 0, near the paper's 6.88) and 500 frames are our choice.
    "seed004_delta0": _SEED004,
    "seed004_delta10": replace(_SEED004, delta=10.0),
}
