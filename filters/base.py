"""The interface every back end shares: ``Filter(model, **params).run(y) -> states``, and for the Kalman
family ``run_from(y, carry) -> (states, carry)`` to continue a run where a previous call stopped.

A back end subclasses :class:`Filter`, lists its parameters with their defaults in ``DEFAULTS`` and
implements, on one batch of independent two-state coordinate problems (every coordinate of every track is
one "channel"), either ``_run_axes`` (a plain run: the FIR family) or ``_run_axes_from`` (a run that starts
from a carried state and returns the state it ends in: the Kalman family; ``_run_axes`` then follows from
it). ``run`` / ``run_from`` validate ``y``, broadcast scalar / per-track (B,) parameters, split boxes into
channels and assemble the (B, T, K) state array (positions first, then velocities).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from filters.model import StateSpaceModel
from filters.validation import broadcast_params, check_measurements


@dataclass(frozen=True, eq=False)
class Carry:
    """Where a Kalman-family run stopped, per track: what :meth:`Filter.run_from` needs to continue it.

    A coordinate whose state in ``x`` (and covariance block in ``P``) is NaN has had no finite measurement
    yet and no prior (runs with ``x0=None``): the next call starts it like :meth:`Filter.run` starts a
    track. The arrays are copied and made read-only, so one carry can start any number of runs.

    >>> import numpy as np, filters
    >>> model, y = filters.constant_velocity(0.05), np.sin(np.arange(20.0))[:, None]
    >>> first, carry = filters.make("kf", model, sigma_w=5.0).run_from(y[:12])
    >>> rest, carry = filters.make("kf", model, sigma_w=5.0).run_from(y[12:], carry)
    >>> bool(np.allclose(np.concatenate([first, rest]), filters.make("kf", model, sigma_w=5.0).run(y)))
    True
    >>> carry.x.shape, carry.P.shape, carry.repeat(3).x.shape
    ((1, 2), (1, 2, 2), (3, 2))
    """

    x: np.ndarray  # (B, K) posterior state at the last frame: positions (units), then velocities (units/s)
    P: np.ndarray  # (B, K, K) its covariance, block-diagonal per coordinate
    y_last: np.ndarray  # (B, M) the last frame's measurement (units), NaN if it was missing
    measured: np.ndarray  # (B, M) bool: the coordinate has had a finite measurement (kf_cmn: with a prior,
    #                       the first one is a y-update, later ones use z_n = y_n − ψ y_{n-1})
    c: np.ndarray | None = None  # (B, n_c) ukf camera_motion only: apparent background velocity c (units/s)
    #                               of the first n_c = min(M, 2) coordinates (filters.ukf)
    P_c: np.ndarray | None = None  # (B, n_c, 3) covariance of c with [position, velocity, c] of its coordinate

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                arr = np.array(value, dtype=bool if f.name == "measured" else float)
                arr.setflags(write=False)
                object.__setattr__(self, f.name, arr)
        if (self.c is None) != (self.P_c is None):
            raise ValueError("carry.c and carry.P_c must be given together (ukf camera states) or both be None")

    def repeat(self, n: int) -> Carry:
        """This one-track carry (B = 1) for ``n`` tracks, e.g. to continue ``n`` candidate parameter sets
        from one state: every field repeated n times along the track axis."""
        if self.x.ndim != 2 or self.x.shape[0] != 1:
            raise ValueError(f"repeat needs a one-track carry; carry.x has shape {self.x.shape}, allowed (1, K)")
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n={n!r}; allowed: an integer >= 1")
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        return Carry(**{k: None if v is None else np.repeat(v, n, axis=0) for k, v in values.items()})


@dataclass(frozen=True, eq=False)
class AxisCarry:
    """A :class:`Carry` split into C one-coordinate channels (channel c = track c // M, coordinate c % M)."""

    x: np.ndarray  # (C, 2) [position, velocity]; NaN for a channel that has no state yet
    P: np.ndarray  # (C, 2, 2)
    c: np.ndarray | None = None  # (B·n_c,) camera states, track-major (the order of the camera channels)
    P_c: np.ndarray | None = None  # (B·n_c, 3)
    # the measurement history: given to the back ends; in what they return it is None (run_from fills it)
    y_last: np.ndarray | None = None  # (C,)
    measured: np.ndarray | None = None  # (C,) bool


class Filter(ABC):
    """A configured filter. Construct with :func:`filters.make`; call :meth:`run` on measurements.

    ``params`` holds the validated parameters, each a float/int array of shape () or (B,).
    """

    name: ClassVar[str]
    DEFAULTS: ClassVar[dict[str, Any]]  # every accepted parameter and its default
    PER_TRACK: ClassVar[tuple[str, ...]]  # parameters that may be scalars or (B,) arrays, one per track

    def __init__(self, model: StateSpaceModel, **params: Any) -> None:
        unknown = sorted(set(params) - set(self.DEFAULTS))
        if unknown:
            raise ValueError(
                f"{self.name}: unknown parameter(s) {unknown}; allowed: {sorted(self.DEFAULTS)}"
            )
        self.model = model
        self.params = self._validate({**self.DEFAULTS, **params})

    @property
    def camera_coordinates(self) -> int:
        """How many leading coordinates carry camera states (and take the camera velocity ``u``); 0 unless
        the back end models camera motion (:class:`filters.ukf.UKF` with ``camera_motion=True``)."""
        return 0

    @abstractmethod
    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        """Check every parameter (ValueError naming it, its value and the allowed range)."""

    def _run_axes(self, z: np.ndarray, params: dict[str, Any], positions_only: bool = False) -> np.ndarray:
        """Filter channels ``z`` (C, T) of one coordinate each (channel c = track c // M, coordinate
        c % M); the ``PER_TRACK`` parameters arrive as arrays (C,), the others as validated.

        Returns posterior two-state estimates (C, T, 2) = [position, velocity] at every frame
        (``positions_only``: the velocities may be left NaN where that saves work)."""
        return self._run_axes_from(z, params, None, None)[0]

    def _run_axes_from(self, z: np.ndarray, params: dict[str, Any], start: AxisCarry | None,
                       u: np.ndarray | None) -> tuple[np.ndarray, AxisCarry]:
        """As ``_run_axes``, continuing from ``start`` (None: the start of every track) with the camera
        velocity ``u`` (C, T) (NaN where missing and on coordinates without camera states) or None.
        Returns the estimates (C, T, 2) and the state after the last frame."""
        raise NotImplementedError(f"{self.name} cannot continue a run from a Carry (run_from); only the Kalman "
                                  "family (kf, kf_cmn, ukf) can: re-run FIR filters on the measurement history")

    def run(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Filter ``y`` shaped (T, M) or (B, T, M); NaN = missing. Returns states (T, K) or (B, T, K).

        ``u``: only for back ends with camera states (``camera_coordinates`` = n_c > 0): the measured apparent
        background velocity (T, n_c) or (B, T, n_c), units/s, NaN where unavailable (see filters.ukf)."""
        z, params, u_axes, n_tracks, batched = self._channels(y, u)
        axes = self._run_axes(z, params) if u_axes is None else self._run_axes_from(z, params, None, u_axes)[0]
        states = merge_axes(axes, n_tracks, self.model.M)
        return states if batched else states[0]

    def positions(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The position estimates only, (T, M) or (B, T, M): ``run(y, u)[..., :M]``, cheaper where a back end
        can skip the velocities (the FIR family: half the work of its full-window convolution)."""
        z, params, u_axes, n_tracks, batched = self._channels(y, u)
        if u_axes is None:
            axes = self._run_axes(z, params, positions_only=True)
        else:
            axes = self._run_axes_from(z, params, None, u_axes)[0]
        M = self.model.M
        out = axes[..., 0].reshape(n_tracks, M, -1).transpose(0, 2, 1)
        return out if batched else out[0]

    def run_from(self, y: np.ndarray, carry: Carry | None = None,
                 u: np.ndarray | None = None) -> tuple[np.ndarray, Carry]:
        """Continue a run: filter ``y`` (T, M) or (B, T, M) starting from ``carry`` (the state a previous call
        ended in; None = the start of every track, then the states equal ``run(y, u)``). The parameters may
        differ from the previous call's: they apply from the first frame of ``y`` on.

        Returns the states (T, K) or (B, T, K) and the :class:`Carry` after the last frame (B = 1 for a
        (T, M) input; ``carry`` must have the batch size of ``y``, see :meth:`Carry.repeat`)."""
        z, params, u_axes, n_tracks, batched = self._channels(y, u)
        start = None if carry is None else _split_carry(carry, n_tracks, self.model.M, self.camera_coordinates)
        axes, end = self._run_axes_from(z, params, start, u_axes)
        measured = ~np.isnan(z).all(axis=1) if start is None else start.measured | ~np.isnan(z).all(axis=1)
        end = replace(end, y_last=z[:, -1], measured=measured)
        states = merge_axes(axes, n_tracks, self.model.M)
        return (states if batched else states[0]), _merge_carry(end, n_tracks, self.model.M)

    def _channels(self, y: np.ndarray, u: np.ndarray | None) -> tuple[np.ndarray, dict[str, Any],
                                                                        np.ndarray | None, int, bool]:
        """Validated ``y`` and ``u`` as channels (C, T), the per-channel parameters, B, and whether batched."""
        Y, batched = check_measurements(y, self.model.M)
        n_tracks, T, M = Y.shape
        per_track = {k: v for k, v in self.params.items() if k in self.PER_TRACK}
        per_track = broadcast_params(per_track, n_tracks, batched)
        per_channel = {k: np.repeat(v, M) for k, v in per_track.items()}
        fixed = {k: v for k, v in self.params.items() if k not in per_channel}
        z = Y.transpose(0, 2, 1).reshape(n_tracks * M, T)
        return z, {**fixed, **per_channel}, self._input_channels(u, Y.shape, batched), n_tracks, batched

    def _input_channels(self, u: np.ndarray | None, shape: tuple[int, int, int], batched: bool) -> np.ndarray | None:
        """The camera velocity ``u`` as channels (C, T), NaN on coordinates without camera states."""
        if u is None:
            return None
        n_c = self.camera_coordinates
        if n_c == 0:
            raise ValueError(f"u (camera velocity) was given but this {self.name} filter has no camera states "
                             "(only ukf with camera_motion=True has); allowed: u=None")
        n_tracks, T, M = shape
        U = np.asarray(u, dtype=float)
        want = (n_tracks, T, n_c) if batched else (T, n_c)
        if U.shape != want:
            raise ValueError(f"u has shape {U.shape}; allowed: {want} (y has shape {(n_tracks, T, M)[not batched:]})")
        if np.any(np.isinf(U)):
            raise ValueError("u contains ±inf; allowed: finite values, or NaN where unavailable")
        u_axes = np.full((n_tracks, M, T), np.nan)
        u_axes[:, :n_c] = U.reshape(n_tracks, T, n_c).transpose(0, 2, 1)
        return u_axes.reshape(n_tracks * M, T)


def merge_axes(axes: np.ndarray, n_tracks: int, M: int) -> np.ndarray:
    """(B·M, T, 2) per-coordinate [p, v] → (B, T, 2M) with positions first, then velocities."""
    T = axes.shape[1]
    per = axes.reshape(n_tracks, M, T, 2)
    return np.concatenate([per[..., 0], per[..., 1]], axis=1).transpose(0, 2, 1)


def _split_carry(carry: Carry, n_tracks: int, M: int, n_c: int) -> AxisCarry:
    """Check a :class:`Carry` against y's batch B and the model, and split it into channels."""
    if not isinstance(carry, Carry):
        raise ValueError(f"carry is a {type(carry).__name__}; allowed: None or a filters.base.Carry")
    K = 2 * M
    wants = {"x": (n_tracks, K), "P": (n_tracks, K, K), "y_last": (n_tracks, M), "measured": (n_tracks, M),
             "c": (n_tracks, n_c), "P_c": (n_tracks, n_c, 3)}
    for name, want in wants.items():
        value = getattr(carry, name)
        if name in ("c", "P_c") and n_c == 0:
            if value is not None:
                raise ValueError(f"carry.{name} is given but this filter has no camera states; allowed: None")
        elif value is None or value.shape != want:
            shape = None if value is None else value.shape
            raise ValueError(f"carry.{name} has shape {shape}; allowed: {want} (B={n_tracks} tracks of y, "
                             f"K={K}, M={M}{f', n_c={n_c} camera coordinates' if n_c else ''})")
        if value is not None and np.any(np.isinf(value)):
            raise ValueError(f"carry.{name} contains ±inf; allowed: finite values (NaN: not started / missing)")
    x = carry.x.reshape(n_tracks, 2, M).transpose(0, 2, 1).reshape(-1, 2)
    P = coordinate_blocks(carry.P, M, "carry.P").reshape(-1, 2, 2)
    waiting = np.isnan(x)
    if np.any(waiting.any(axis=1) != waiting.all(axis=1)) or not np.all(np.isfinite(P[~waiting[:, 0]])):
        raise ValueError("carry.x / carry.P: a coordinate's position and velocity must both be finite (with a "
                         "finite covariance block) or both be NaN (not started)")
    measured = carry.measured.reshape(-1)
    if np.any(measured & waiting[:, 0]):
        raise ValueError("carry.measured is True for a coordinate whose carry.x is NaN; allowed: a measured "
                         "coordinate has a finite state")
    c = None if carry.c is None else carry.c.reshape(-1)
    P_c = None if carry.P_c is None else carry.P_c.reshape(-1, 3)
    return AxisCarry(x=x, P=P, c=c, P_c=P_c, y_last=carry.y_last.reshape(-1), measured=measured)


def _merge_carry(end: AxisCarry, n_tracks: int, M: int) -> Carry:
    """Channels → the per-track :class:`Carry` (full-model layout, positions first)."""
    x = end.x.reshape(n_tracks, M, 2).transpose(0, 2, 1).reshape(n_tracks, 2 * M)
    P = block_diagonal(end.P.reshape(n_tracks, M, 2, 2))
    c = None if end.c is None else end.c.reshape(n_tracks, -1)
    P_c = None if end.P_c is None else end.P_c.reshape(n_tracks, -1, 3)
    return Carry(x=x, P=P, y_last=end.y_last.reshape(n_tracks, M), measured=end.measured.reshape(n_tracks, M),
                 c=c, P_c=P_c)


def block_diagonal(blocks: np.ndarray) -> np.ndarray:
    """Per-coordinate 2×2 blocks (B, M, 2, 2) → full-model covariances (B, K, K) (positions first)."""
    n_tracks, M = blocks.shape[:2]
    P = np.zeros((n_tracks, 2, M, 2, M))
    idx = np.arange(M)
    P[:, :, idx, :, idx] = blocks.transpose(1, 0, 2, 3)  # advanced indices first: (M, B, 2, 2)
    return P.reshape(n_tracks, 2 * M, 2 * M)


def split_state(vec: np.ndarray, M: int) -> np.ndarray:
    """A full-model state vector (K,) → per-coordinate [p, v] pairs (M, 2)."""
    vec = np.asarray(vec, dtype=float)
    return np.stack([vec[:M], vec[M:]], axis=-1)


def split_covariance(P: np.ndarray, M: int, name: str = "P0") -> np.ndarray:
    """A full-model covariance (K, K) → per-coordinate 2×2 blocks (M, 2, 2).

    The coordinates are filtered independently, so ``P`` must not couple them: every entry linking two
    different coordinates must be zero (ValueError otherwise)."""
    return coordinate_blocks(np.asarray(P, dtype=float)[None], M, name)[0]


def coordinate_blocks(P: np.ndarray, M: int, name: str) -> np.ndarray:
    """Full-model covariances (B, K, K) → per-coordinate 2×2 blocks (B, M, 2, 2); ValueError naming ``name``
    if an entry linking two different coordinates is not zero (NaN blocks allowed)."""
    blocks = np.diagonal(P.reshape(len(P), 2, M, 2, M), axis1=2, axis2=4).transpose(0, 3, 1, 2)
    if not np.array_equal(block_diagonal(blocks), P, equal_nan=True):
        raise ValueError(f"{name} couples different coordinates; allowed: a covariance that is block-diagonal "
                         "per coordinate")
    return blocks
