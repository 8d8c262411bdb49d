"""Action ↔ filter-parameter mapping shared by the environments and the baselines.

An action is a float vector in [-1, 1]^d, one entry per tuned parameter (``tune``, in that order):

| parameter              | mapping from a ∈ [-1, 1]                               | range                          |
|------------------------|--------------------------------------------------------|--------------------------------|
| psi                    | ψ = ψ_max (a + 1) / 2                                  | [0, ψ_max], ψ_max = 0.99       |
| horizon                | N = round(K (N_max / K)^((a + 1) / 2))  (log scale)    | integers [K, N_max]            |
| sigma_w                | σ_w = σ_w,nominal · 10^(D a)             (log scale)   | nominal · [10^-D, 10^D], D=1.5 |
| sigma_v                | σ_v = σ_v,nominal · 10^(D a)             (log scale)   | nominal · [10^-D, 10^D]        |
| std_weight_position    | σ_p = stock · 10^(D a), stock 1/20       (log scale)   | stock · [10^-D, 10^D]          |
| std_weight_velocity    | σ_ṗ = stock · 10^(D a), stock 1/160      (log scale)   | stock · [10^-D, 10^D]          |
| std_aspect_measurement | s_m = stock · 10^(D a), stock 1e-1       (log scale)   | stock · [10^-D, 10^D]          |

The last three are ``bytetrack_kf``'s (:mod:`bboxtune.filters.bytetrack_kf`: its noise weights relative to the box height
and the aspect's measurement std). Their nominal value is ByteTrack's published one (:data:`STOCK`) in every
episode, whatever its σ: the fixed rule of that back end is the stock filter practitioners run, so its reward
measures the gain over stock ByteTrack. Every back end's :class:`Nominal` carries them (untouched by the others).
One factor on both weights scales that filter's Q, R and P₀ alike, so its estimates depend on their ratio only
(as OFIR's on σ_w / σ_v); the aspect's gain depends on s_m, which neither weight touches.

The horizon is mapped on an absolute log scale rather than as a multiplier on the rule's N_opt: the rule's
own N_opt is computed from nominal σ that can be off by a decade, so a multiplier would tie the reachable
range to a possibly wrong centre; log N_opt is in the observation instead, so a policy can still learn a
residual on it. Entries with |a| ≤ 1 + 1e-6 are accepted (the excess is clipped: float32 round-off);
anything further out, NaN or ±inf raises ``ValueError``; so does a wrong shape (an env step takes exactly
(d,), ``score`` a batch (A, d) with A >= 1); a non-numeric or bool dtype raises ``TypeError``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from bboxtune.filters.bytetrack_kf import ByteTrackKF
from bboxtune.filters.horizon import rule_horizon
from bboxtune.filters.registry import NAMES

# bytetrack_kf's tunable parameters at their published values (the nominal of every episode: module docstring)
STOCK: dict[str, float] = {k: ByteTrackKF.DEFAULTS[k] for k in
                           ("std_weight_position", "std_weight_velocity", "std_aspect_measurement")}
SIGMA_PARAMETERS: tuple[str, ...] = ("psi", "horizon", "sigma_w", "sigma_v")  # what the bboxtune.filters.NAMES back ends take
TUNABLE: tuple[str, ...] = (*SIGMA_PARAMETERS, *STOCK)

# Which parameters each back end accepts from the tuner (the others stay at their nominal values).
ACCEPTS: dict[str, tuple[str, ...]] = {
    "kf": ("sigma_w", "sigma_v"),
    "kf_cmn": ("psi", "sigma_w", "sigma_v"),
    "ufir": ("horizon",),
    "ufir_cmn": ("psi", "horizon"),
    "ofir": ("horizon", "sigma_w", "sigma_v"),
    "oufir": ("horizon", "sigma_w", "sigma_v"),
    "fir": ("horizon", "sigma_w", "sigma_v"),
    "ukf": ("sigma_w", "sigma_v"),
    "bytetrack_kf": tuple(STOCK),  # std_aspect_measurement on request only (tune=...)
}
# The back ends of the envs: the eight of bboxtune.filters.NAMES and ByteTrack's box KF (sort_kf has no parameters to tune)
BACKENDS: tuple[str, ...] = (*NAMES, "bytetrack_kf")

# Default ``tune``: OFIR/OUFIR/FIR gains depend on σ_w/σ_v only through their ratio, so σ_v stays nominal.
DEFAULT_TUNE: dict[str, tuple[str, ...]] = {
    "kf": ("sigma_w", "sigma_v"),
    "kf_cmn": ("psi", "sigma_w", "sigma_v"),
    "ufir": ("horizon",),
    "ufir_cmn": ("psi", "horizon"),
    "ofir": ("horizon", "sigma_w"),
    "oufir": ("horizon", "sigma_w"),
    "fir": ("horizon", "sigma_w"),
    "ukf": ("sigma_w", "sigma_v"),
    "bytetrack_kf": ("std_weight_position", "std_weight_velocity"),  # the two std weights
}

_TOLERANCE = 1e-6


def parameter_family(backend: str) -> tuple[str, ...]:
    """The parameters of ``backend``'s family, which records of its runs list (untuned ones at their nominal values):
    :data:`SIGMA_PARAMETERS` for the eight of ``bboxtune.filters.NAMES``, bytetrack_kf's three (:data:`STOCK`) for it."""
    return tuple(STOCK) if backend == "bytetrack_kf" else SIGMA_PARAMETERS


K_AXIS = 2  # state size of one coordinate's constant-velocity model (the smallest horizon)


@dataclass(frozen=True)
class Nominal:
    """The nominal parameter values of one episode (what the fixed rule uses)."""

    sigma_w: float  # coordinate units / s², acceleration noise std
    sigma_v: float  # coordinate units, white measurement noise std
    psi: float  # CMN coloredness assumed by the rule
    horizon: int  # frames, the rule's N = round(N_opt(σ_v, σ_w, τ)) within [K, N_max]
    # bytetrack_kf's: ByteTrack's published values in every episode (its rule is the stock filter)
    std_weight_position: float = STOCK["std_weight_position"]
    std_weight_velocity: float = STOCK["std_weight_velocity"]
    std_aspect_measurement: float = STOCK["std_aspect_measurement"]

    @classmethod
    def of_rule(cls, sigma_v: float, sigma_w: float, tau: float, psi: float, horizon_max: int) -> Nominal:
        """The fixed rule's parameters for nominal σ_v, σ_w (px, px/s²) at frame interval ``tau`` (s): ψ as
        given and N = N_opt(σ_v, σ_w, τ) within [``K_AXIS``, ``horizon_max``] (:func:`bboxtune.filters.horizon.rule_horizon`)."""
        horizon = rule_horizon(sigma_v, sigma_w, tau, K_AXIS, max_horizon=horizon_max)
        return cls(sigma_w=sigma_w, sigma_v=sigma_v, psi=psi, horizon=int(horizon))

    def as_params(self) -> dict[str, np.ndarray]:
        """The parameters as one candidate of a filter run: {name: array (1,)} for every name in ``TUNABLE``."""
        return {k: np.array([getattr(self, k)]) for k in TUNABLE}

    @staticmethod
    def stacked(nominals: list[Nominal]) -> dict[str, np.ndarray]:
        """Many episodes' parameters as the candidates of one filter run: {name: array (n,)}, row i
        ``nominals[i].as_params()``."""
        return {k: np.array([getattr(n, k) for n in nominals]) for k in TUNABLE}


@dataclass(frozen=True)
class ActionMap:
    """Maps actions in [-1, 1]^d to the physical parameters of ``tune`` and back."""

    tune: tuple[str, ...]
    K: int  # state size of one coordinate's model (smallest horizon)
    horizon_max: int = 400  # frames, N_max
    psi_max: float = 0.99
    sigma_decades: float = 1.5  # D: σ (and bytetrack_kf's weights) range over nominal · 10^[-D, D]

    def __post_init__(self) -> None:
        unknown = [p for p in self.tune if p not in TUNABLE]
        if unknown or len(set(self.tune)) != len(self.tune) or not self.tune:
            raise ValueError(f"tune={self.tune!r}: allowed a non-empty tuple of distinct names from {TUNABLE}")
        if not self.K <= self.horizon_max:
            raise ValueError(f"horizon_max={self.horizon_max} must be >= K={self.K}")

    @property
    def dim(self) -> int:
        return len(self.tune)

    def check(self, actions: np.ndarray, name: str = "action") -> np.ndarray:
        """Validate actions shaped (d,) or (A, d) with A >= 1: real numbers (not bool), finite, within
        [-1, 1] (see the module docstring for the 1e-6 float32 tolerance); returns float64 (A, d). Errors name the
        argument as ``name``."""
        try:
            raw = np.asarray(actions)
        except (ValueError, TypeError) as err:  # ragged nesting and the like
            raise ValueError(f"{name} {actions!r} is not an array of numbers ({err})") from None
        if raw.dtype.kind not in "iuf":
            raise TypeError(f"{name} has dtype {raw.dtype}; allowed: real numbers (float or integer)")
        a = raw.astype(np.float64)
        a2 = a.reshape(1, -1) if a.ndim == 1 else a
        if a2.ndim != 2 or a2.shape[1] != self.dim or a2.shape[0] == 0:
            raise ValueError(f"{name} has shape {a.shape}; allowed ({self.dim},) or (A, {self.dim}) with A >= 1 "
                             f"for tune={self.tune}")
        if not (np.abs(a2) <= 1 + _TOLERANCE).all():  # NaN and ±inf fail this too
            if not np.isfinite(a2).all():
                raise ValueError(f"{name} {a.tolist() if a.size <= 8 else a.shape} contains NaN or inf; allowed finite "
                                 "values in [-1, 1]")
            worst = float(a2.flat[np.argmax(np.abs(a2))])
            raise ValueError(f"{name} entry {worst} is out of range: allowed [-1, 1]")
        return np.minimum(np.maximum(a2, -1.0), 1.0)

    def check_one(self, action: np.ndarray) -> np.ndarray:
        """Validate one action: shape exactly (d,) (a batch is refused), otherwise as :meth:`check`; returns (1, d)."""
        try:
            shape = np.shape(action)
        except (ValueError, TypeError):  # ragged nesting
            shape = None
        if shape != (self.dim,):
            raise ValueError(f"action has shape {shape}; allowed ({self.dim},), one action for tune={self.tune} "
                             "(score() takes batches)")
        return self.check(action)

    def to_params(self, actions: np.ndarray, nominal: Nominal | Sequence[Nominal], name: str = "action"
                  ) -> dict[str, np.ndarray]:
        """Actions (d,) or (A, d) → {name: array (A,)} for every parameter in ``TUNABLE`` (untuned ones at their
        nominal values); ``nominal`` one for every row, or a sequence of A, row a's for action a (a batch of
        episodes)."""
        a = self.check(actions, name)
        n = a.shape[0]
        if isinstance(nominal, Nominal):
            values = {k: getattr(nominal, k) for k in TUNABLE}
        else:
            if len(nominal) != n:
                raise ValueError(f"{len(nominal)} nominal parameter sets for {n} actions; allowed: one per action")
            values = {k: np.array([getattr(x, k) for x in nominal]) for k in TUNABLE}
        out = {k: np.full(n, values[k], dtype=np.int64 if k == "horizon" else np.float64) for k in TUNABLE}
        for j, name in enumerate(self.tune):
            u = (a[:, j] + 1.0) / 2.0
            if name == "psi":
                out[name] = self.psi_max * u
            elif name == "horizon":
                out[name] = np.rint(self.K * (self.horizon_max / self.K) ** u).astype(np.int64)
            else:
                out[name] = values[name] * 10.0 ** (self.sigma_decades * a[:, j])
        return out

    def to_actions(self, params: Mapping[str, np.ndarray | float], nominal: Nominal) -> np.ndarray:
        """Physical parameters → actions (A, d): the inverse of :meth:`to_params` (for baselines).

        Values outside the reachable range raise ``ValueError``."""
        cols = []
        for name in self.tune:
            v = np.atleast_1d(np.asarray(params[name], dtype=np.float64))
            if name == "psi":
                a = 2.0 * v / self.psi_max - 1.0
            elif name == "horizon":
                a = (2.0 * np.log(v / self.K) / np.log(self.horizon_max / self.K) - 1.0 if self.horizon_max > self.K
                     else np.zeros_like(v))
            else:
                a = np.log10(v / getattr(nominal, name)) / self.sigma_decades
            if np.any(~np.isfinite(a)) or np.any(np.abs(a) > 1 + 1e-9):
                raise ValueError(f"{name}={v.tolist()} is outside the action range of this env")
            cols.append(np.clip(a, -1.0, 1.0))
        return np.stack(cols, axis=-1)
