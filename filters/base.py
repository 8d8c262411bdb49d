"""The interface every back end shares: ``Filter(model, **params).run(y) -> states``, and
``run_from(y, carry) -> (states, carry)`` to continue a run where a previous call stopped (the Kalman family
carries its state, a :class:`Carry`; the FIR family its measurement history, :class:`bboxtune.filters.history.History`).

A back end subclasses :class:`Filter`, lists its parameters with their defaults in ``DEFAULTS`` and
implements, on one batch of independent two-state coordinate problems (every coordinate of every track is
one "channel"), either ``_run_axes`` (a plain run: the FIR family) or ``_run_axes_from`` (a run that starts
from a carried state and returns the state it ends in: the Kalman family; ``_run_axes`` then follows from
it). ``run`` / ``run_from`` validate ``y``, broadcast scalar / per-track (B,) parameters, split boxes into
channels and assemble the (B, T, K) state array (positions first, then velocities).

Batches run in chunks of whole tracks of at most :data:`CHUNK_SAMPLES` channel-frames, so the working memory
beyond ``y`` and the result does not grow with B (20,000 box tracks × 500 frames with missing frames: UFIR once
needed 12–13 GB, now ~1.3 GB peak RSS in all); small calls are one chunk, unchanged. B = 0 tracks or T = 0 frames
give empty results. Every estimate from a channel's first finite measurement on is checked to be finite
(``FloatingPointError`` otherwise: inside the ranges of :mod:`bboxtune.filters.validation` it never happens).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar, cast

import numpy as np

from bboxtune.filters.blocks import block_diagonal, coordinate_blocks
from bboxtune.filters.finite_check import first_nonfinite, write_positions
from bboxtune.filters.model import StateSpaceModel, check_model
from bboxtune.filters.threads import limited_blas
from bboxtune.filters.validation import broadcast_params, check_measurements, check_values

# Channel-frames (tracks × coordinates × frames) filtered per chunk: bounds the working memory of a call
# (the heaviest back end, UFIR with missing samples, needs ~300 bytes per channel-frame: ~300 MB a chunk)
CHUNK_SAMPLES = 1 << 20
CANNOT_CONTINUE = "{name} implements neither _run_axes_from (a carried state) nor its own run_from"


@dataclass(frozen=True, eq=False)
class Carry:
    """Where a Kalman-family run stopped, per track: what :meth:`Filter.run_from` needs to continue it.

    A coordinate whose state in ``x`` (and covariance block in ``P``) is NaN has had no finite measurement
    yet and no prior (runs with ``x0=None``): the next call starts it like :meth:`Filter.run` starts a
    track. The arrays are copied and made read-only, so one carry can start any number of runs.

    >>> import numpy as np
    >>> from bboxtune import filters
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
    y_last: np.ndarray  # (B, M) the last finite measurement (units), NaN if the coordinate has none yet
    measured: np.ndarray  # (B, M) bool: the coordinate has had a finite measurement (kf_cmn: with a prior,
    #                       the first one is a y-update, later ones use z_n = y_n − ψ^{g+1} y_last)
    c: np.ndarray | None = None  # (B, n_c) ukf camera_motion only: apparent background velocity c (units/s)
    #                               of the first n_c = min(M, 2) coordinates (bboxtune.filters.ukf)
    P_c: np.ndarray | None = None  # (B, n_c, 3) covariance of c with [position, velocity, c] of its coordinate
    missed: np.ndarray | None = None  # (B, M) frames after y_last's up to the last one; None → 0 (not given)

    def __post_init__(self) -> None:
        if self.missed is None:
            object.__setattr__(self, "missed", np.zeros(np.shape(self.y_last)))
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                arr = np.array(value, dtype=bool if f.name == "measured" else float)
                arr.setflags(write=False)
                object.__setattr__(self, f.name, arr)
        if (self.c is None) != (self.P_c is None):
            raise ValueError("carry.c and carry.P_c must be given together (ukf camera states) or both be None")

    def slice(self, rows: slice) -> Carry:
        """The carry of tracks ``rows`` (every field sliced along the track axis)."""
        values: dict[str, Any] = {f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[rows]
                                  for f in fields(self)}
        return Carry(**values)

    def take(self, index: np.ndarray) -> Carry:
        """The carry of the tracks ``index`` (an int array, in its order; e.g. a tracker's live tracks)."""
        values: dict[str, Any] = {f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[index]
                                  for f in fields(self)}
        return Carry(**values)

    def repeat(self, n: int) -> Carry:
        """This one-track carry (B = 1) for ``n`` tracks, e.g. to continue ``n`` candidate parameter sets
        from one state: every field repeated n times along the track axis."""
        if self.x.ndim != 2 or self.x.shape[0] != 1:
            raise ValueError(f"repeat needs a one-track carry; carry.x has shape {self.x.shape}, allowed (1, K)")
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n={n!r}; allowed: an integer >= 1")
        values: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self)}
        repeated: dict[str, Any] = {k: None if v is None else np.repeat(v, n, axis=0) for k, v in values.items()}
        return Carry(**repeated)


@dataclass(frozen=True, eq=False)
class AxisCarry:
    """A :class:`Carry` split into C one-coordinate channels (channel c = track c // M, coordinate c % M)."""

    x: np.ndarray  # (C, 2) [position, velocity]; NaN for a channel that has no state yet
    P: np.ndarray  # (C, 2, 2)
    c: np.ndarray | None = None  # (B·n_c,) camera states, track-major (the order of the camera channels)
    P_c: np.ndarray | None = None  # (B·n_c, 3)
    # the measurement history: given to the back ends; in what they return it is None (run_from fills it)
    y_last: np.ndarray | None = None  # (C,) the last finite measurement, NaN if none yet
    measured: np.ndarray | None = None  # (C,) bool
    missed: np.ndarray | None = None  # (C,) int: frames after y_last's frame up to the last one


class Filter(ABC):
    """A configured filter. Construct with :func:`bboxtune.filters.make`; call :meth:`run` on measurements.

    ``params`` holds the validated parameters, each a float/int array of shape () or (B,).
    """

    name: ClassVar[str]
    DEFAULTS: ClassVar[dict[str, Any]]  # every accepted parameter and its default
    PER_TRACK: ClassVar[tuple[str, ...]]  # parameters that may be scalars or (B,) arrays, one per track
    IN_FRAMES: ClassVar[bool] = False  # exact in frame units: tracks of any τ run as one batch at τ = 1
    SPLIT_TRACKS: ClassVar[bool] = True  # a batch's tracks may run in threads (filters.batch.track_positions)

    @classmethod
    def params_in_frames(cls, params: dict[str, Any], tau: float | np.ndarray) -> dict[str, Any]:
        """``params`` with every time-dependent quantity in frame units, for a run at τ = 1 that gives the
        same positions (velocities come out in units per frame, × τ): σ_w → σ_w τ², since the state [p, v τ]
        has ``B = τ² [1/2, 1]ᵀ``; ``tau`` a scalar or per track (B,). Exact (to round-off) for the back ends
        with ``IN_FRAMES``; those with further such parameters (a prior) extend this."""
        if "sigma_w" not in params:  # a partial set (the defaults are filled in later)
            return dict(params)
        return {**params, "sigma_w": np.asarray(params["sigma_w"]) * np.asarray(tau) ** 2}

    def __init__(self, model: StateSpaceModel, **params: Any) -> None:
        self.model = check_model(model)
        self.check_names(params)
        self.params = self._validate({**self.DEFAULTS, **params})

    @classmethod
    def check_names(cls, params: Mapping[str, Any]) -> None:
        """ValueError naming the parameters in ``params`` that this back end does not take."""
        unknown = sorted(set(params) - set(cls.DEFAULTS))
        if unknown:
            raise ValueError(f"{cls.name}: unknown parameter(s) {unknown}; allowed: {sorted(cls.DEFAULTS)}")

    @property
    def camera_coordinates(self) -> int:
        """How many leading coordinates carry camera states (and take the camera velocity ``u``); 0 unless
        the back end models camera motion (:class:`bboxtune.filters.ukf.UKF` with ``camera_motion=True``)."""
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
        raise NotImplementedError(CANNOT_CONTINUE.format(name=self.name))

    @limited_blas
    def run(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Filter ``y`` shaped (T, M) or (B, T, M); NaN = missing. Returns states (T, K) or (B, T, K).

        ``u``: only for back ends with camera states (``camera_coordinates`` = n_c > 0): the measured apparent
        background velocity (T, n_c) or (B, T, n_c), units/s, NaN where unavailable (see bboxtune.filters.ukf).
        B = 0 or T = 0 give an empty result of that shape. Large batches run in chunks of tracks
        (:data:`CHUNK_SAMPLES`), so the working memory beyond ``y`` and the result stays bounded."""
        Y, U, per_track, batched = self._inputs(y, u)
        n_tracks, T, M = Y.shape
        states = np.empty((n_tracks, T, 2 * M))
        for rows, z, params, u_axes in self._chunks(Y, U, per_track):
            axes = self._run_axes(z, params) if u_axes is None else self._run_axes_from(z, params, None, u_axes)[0]
            self._check_finite(axes, z, rows, params)
            states[rows] = merge_axes(axes, rows.stop - rows.start, M)
        return states if batched else states[0]

    @limited_blas
    def positions(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The position estimates only, (T, M) or (B, T, M): ``run(y, u)[..., :M]``, cheaper where a back end
        can skip the velocities (the FIR family: half the work of its full-window convolution)."""
        Y, U, per_track, batched = self._inputs(y, u)
        n_tracks, T, M = Y.shape
        out = np.empty((n_tracks, T, M))
        for rows, z, params, u_axes in self._chunks(Y, U, per_track):
            if u_axes is None:
                axes = self._run_axes(z, params, positions_only=True)
            else:
                axes = self._run_axes_from(z, params, None, u_axes)[0]
            self._raise_nonfinite(write_positions(axes, z, out[rows]), z, rows, params)
        return out if batched else out[0]

    # typed Any, as positions_from: a back end's carry is its own type (the FIR family's run_from takes and returns
    # a History); this implementation, the Kalman family's, takes and returns a Carry
    @limited_blas
    def run_from(self, y: np.ndarray, carry: Any = None, u: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        """Continue a run: filter ``y`` (T, M) or (B, T, M) starting from ``carry`` (the state a previous call
        ended in; None = the start of every track, then the states equal ``run(y, u)``). The parameters may
        differ from the previous call's: they apply from the first frame of ``y`` on.

        Returns the states (T, K) or (B, T, K) and the :class:`Carry` after the last frame (B = 1 for a
        (T, M) input; ``carry`` must have the batch size of ``y``, see :meth:`Carry.repeat`). With T = 0 frames
        the carry is returned unchanged (None: a carry of tracks that have not started)."""
        Y, U, per_track, batched = self._inputs(y, u)
        n_tracks, T, M = Y.shape
        n_c = self.camera_coordinates
        if carry is not None:
            _split_carry(carry, n_tracks, M, n_c)  # validate once, for the whole batch
        states = np.empty((n_tracks, T, 2 * M))
        end_carry: Carry
        ends: list[Carry] = []
        for rows, z, params, u_axes in self._chunks(Y, U, per_track):
            start = None if carry is None else _split_carry(carry.slice(rows), rows.stop - rows.start, M, n_c)
            axes, end = self._run_axes_from(z, params, start, u_axes)
            self._check_finite(axes, z, rows, params)
            end = replace(end, **measurement_history(z, start))
            states[rows] = merge_axes(axes, rows.stop - rows.start, M)
            ends.append(_merge_carry(end, rows.stop - rows.start, M))
        if T == 0:
            end_carry = carry if carry is not None else not_started(n_tracks, M, n_c)
        elif ends:
            merged: dict[str, Any] = {f.name: None if getattr(ends[0], f.name) is None else
                                      np.concatenate([getattr(e, f.name) for e in ends]) for f in fields(Carry)}
            end_carry = Carry(**merged)
        else:
            end_carry = not_started(0, M, n_c)
        return (states if batched else states[0]), end_carry

    def positions_from(self, y: np.ndarray, carry: Any = None, u: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        """:meth:`run_from`'s position estimates only, (T, M) or (B, T, M), and the carry after the last frame."""
        states, end = self.run_from(y, carry, u)
        return states[..., : self.model.M], end

    def _check_finite(self, axes: np.ndarray, z: np.ndarray, rows: slice, params: dict[str, Any]) -> None:
        """Every estimate (C, T, k) at or after a channel's first finite measurement must be finite: inside the
        documented ranges (:mod:`bboxtune.filters.validation`) it is; a non-finite one is a numerical failure, reported
        rather than returned."""
        self._raise_nonfinite(first_nonfinite(axes, z), z, rows, params)

    def _raise_nonfinite(self, bad: tuple[int, int] | None, z: np.ndarray, rows: slice, params: dict[str, Any]) -> None:
        """The ``FloatingPointError`` of :meth:`_check_finite` for channel, frame ``bad`` (None: nothing to report)."""
        if bad is not None:
            c, t = bad
            M = self.model.M
            used = {k: (v[c] if np.ndim(v) == 1 and len(v) == len(z) else v) for k, v in params.items()}
            raise FloatingPointError(
                f"{self.name}: non-finite estimate at track {rows.start + c // M}, coordinate {c % M}, frame {t}, after "
                f"a finite measurement (parameters {used}, tau={self.model.tau!r}): float64 failed inside the valid "
                "ranges of bboxtune.filters.validation — please report this input")

    def _inputs(self, y: np.ndarray, u: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None,
                                                                      dict[str, np.ndarray], bool]:
        """Validated ``y`` (B, T, M), ``u`` (B, T, n_c) or None, the per-track parameters as (B,) arrays, and
        whether the input was batched."""
        Y, batched = check_measurements(y, self.model.M)
        per_track = {k: v for k, v in self.params.items() if k in self.PER_TRACK}
        return Y, self._check_input(u, Y.shape, batched), broadcast_params(per_track, Y.shape[0], batched), batched

    def _chunks(self, Y: np.ndarray, U: np.ndarray | None, per_track: dict[str, np.ndarray]
                ) -> Iterator[tuple[slice, np.ndarray, dict[str, Any], np.ndarray | None]]:
        """Consecutive chunks of tracks: (track slice, channels z (C, T), per-channel parameters (C,) with the
        shared ones, camera velocity channels (C, T) or None), each at most :data:`CHUNK_SAMPLES` channel-frames
        (at least one track); none for T = 0. Channel c of a chunk = its track c // M, coordinate c % M."""
        n_tracks, T, M = Y.shape
        if T == 0:
            return
        step = max(1, CHUNK_SAMPLES // (T * M))
        fixed = {k: v for k, v in self.params.items() if k not in per_track}
        for first in range(0, n_tracks, step):
            rows = slice(first, min(n_tracks, first + step))
            z = Y[rows].transpose(0, 2, 1).reshape(-1, T)
            params = {**fixed, **{k: np.repeat(v[rows], M) for k, v in per_track.items()}}
            yield rows, z, params, None if U is None else self._input_channels(U[rows], M)

    def _check_input(self, u: np.ndarray | None, shape: tuple[int, int, int], batched: bool) -> np.ndarray | None:
        """The camera velocity ``u`` validated and shaped (B, T, n_c), or None."""
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
        check_values("u", U)
        return U.reshape(n_tracks, T, n_c)

    @staticmethod
    def _input_channels(U: np.ndarray, M: int) -> np.ndarray:
        """The camera velocity (B, T, n_c) as channels (B·M, T), NaN on coordinates without camera states."""
        n_tracks, T, n_c = U.shape
        u_axes = np.full((n_tracks, M, T), np.nan)
        u_axes[:, :n_c] = U.transpose(0, 2, 1)
        return u_axes.reshape(n_tracks * M, T)


def measurement_history(z: np.ndarray, start: AxisCarry | None) -> dict[str, np.ndarray]:
    """``y_last``, ``missed`` and ``measured`` (C,) after the last frame of channels ``z`` (C, T) that continue
    ``start`` (None: not started): the last finite measurement, the frames after it, whether there has been one."""
    C, T = z.shape
    finite = ~np.isnan(z)
    seen = finite.any(axis=1)
    last = T - 1 - np.argmax(finite[:, ::-1], axis=1)  # the last finite frame (where ``seen``)
    y_before = np.full(C, np.nan) if start is None else cast(np.ndarray, start.y_last)
    # a started channel's history (start.y_last, start.missed, start.measured) is always set: _split_carry
    missed_before = np.where(np.isnan(y_before), 0, 0 if start is None else cast(np.ndarray, start.missed) + T)
    return {"y_last": np.where(seen, z[np.arange(C), last], y_before),
            "missed": np.where(seen, T - 1 - last, missed_before),
            "measured": seen if start is None else cast(np.ndarray, start.measured) | seen}


def not_started(n_tracks: int, M: int, n_c: int = 0) -> Carry:
    """The :class:`Carry` of ``n_tracks`` tracks that have not started (no measurement, no state yet)."""
    nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    return Carry(x=nan(n_tracks, 2 * M), P=block_diagonal(nan(n_tracks, M, 2, 2)), y_last=nan(n_tracks, M),
                 measured=np.zeros((n_tracks, M), bool), c=nan(n_tracks, n_c) if n_c else None,
                 P_c=nan(n_tracks, n_c, 3) if n_c else None)


def merge_axes(axes: np.ndarray, n_tracks: int, M: int) -> np.ndarray:
    """(B·M, T, 2) per-coordinate [p, v] → (B, T, 2M) with positions first, then velocities."""
    T = axes.shape[1]
    per = axes.reshape(n_tracks, M, T, 2)
    return np.concatenate([per[..., 0], per[..., 1]], axis=1).transpose(0, 2, 1)


def _split_carry(carry: Carry, n_tracks: int, M: int, n_c: int) -> AxisCarry:
    """Check a :class:`Carry` against y's batch B and the model, and split it into channels."""
    if not isinstance(carry, Carry):
        raise ValueError(f"carry is a {type(carry).__name__}; allowed: None or a bboxtune.filters.base.Carry")
    K = 2 * M
    wants = {"x": (n_tracks, K), "P": (n_tracks, K, K), "y_last": (n_tracks, M), "measured": (n_tracks, M),
             "missed": (n_tracks, M), "c": (n_tracks, n_c), "P_c": (n_tracks, n_c, 3)}
    for name, want in wants.items():
        value = getattr(carry, name)
        if name in ("c", "P_c") and n_c == 0:
            if value is not None:
                raise ValueError(f"carry.{name} is given but this filter has no camera states; allowed: None")
        elif value is None or value.shape != want:
            shape = None if value is None else value.shape
            raise ValueError(f"carry.{name} has shape {shape}; allowed: {want} (B={n_tracks} tracks of y, "
                             f"K={K}, M={M}{f', n_c={n_c} camera coordinates' if n_c else ''})")
        if value is not None and value.size and np.any(np.isinf(value)):
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
    y_last, missed = carry.y_last.reshape(-1), cast(np.ndarray, carry.missed).reshape(-1)  # __post_init__ sets missed
    if np.any(~np.isnan(y_last) & ~measured):
        raise ValueError("carry.y_last is finite for a coordinate that carry.measured marks as not measured; "
                         "allowed: y_last NaN until the coordinate's first finite measurement")
    if not np.all((missed >= 0) & (missed == np.round(missed))):  # NaN fails too
        raise ValueError("carry.missed has an entry that is not a whole number >= 0 (frames since carry.y_last)")
    c = None if carry.c is None else carry.c.reshape(-1)
    P_c = None if carry.P_c is None else carry.P_c.reshape(-1, 3)
    return AxisCarry(x=x, P=P, c=c, P_c=P_c, y_last=y_last, measured=measured, missed=missed.astype(np.int64))


def _merge_carry(end: AxisCarry, n_tracks: int, M: int) -> Carry:
    """Channels → the per-track :class:`Carry` (full-model layout, positions first)."""
    x = end.x.reshape(n_tracks, M, 2).transpose(0, 2, 1).reshape(n_tracks, 2 * M)
    P = block_diagonal(end.P.reshape(n_tracks, M, 2, 2))
    c = None if end.c is None else end.c.reshape(n_tracks, -1)
    P_c = None if end.P_c is None else end.P_c.reshape(n_tracks, -1, 3)
    # the measurement history is set by now (run_from: replace(end, **measurement_history(...)))
    y_last, measured, missed = (cast(np.ndarray, a) for a in (end.y_last, end.measured, end.missed))
    return Carry(x=x, P=P, y_last=y_last.reshape(n_tracks, M), measured=measured.reshape(n_tracks, M),
                 c=c, P_c=P_c, missed=missed.reshape(n_tracks, M))
