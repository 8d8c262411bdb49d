"""The box Kalman filter of ByteTrack and DeepSORT ([Zhang-ByteTrack], [Wojke-DeepSORT]; both code bases share one
``KalmanFilter``), batched over tracks, and :class:`BoxKF`, the whole-box recursion it shares with SORT's
(:mod:`bboxtune.filters.sort_kf`).

ByteTrack's filter, per track, with dt = 1 frame and h the track's height:

* state ``[x, y, a, h, vx, vy, va, vh]`` (centre, aspect a = w / h, height, their rates per frame);
  ``F = [[I, I], [0, I]]``, ``H = [I, 0]``;
* start ("initiate", at the first detection m = [x, y, a, h]): mean [m, 0], P = diag(std²) with std =
  [2σ_p h, 2σ_p h, s_a, 2σ_p h, 10σ_v h, 10σ_v h, s_ȧ, 10σ_v h];
* "predict": Q = diag([σ_p h, σ_p h, s_a, σ_p h, σ_v h, σ_v h, s_ȧ, σ_v h]²), h the current mean height;
* "update" (a detection): R = diag([σ_p h, σ_p h, s_m, σ_p h]²), h the predicted height;
* a missing detection: predict only; frames before the first detection: NaN.

Parameters (per track, scalars or (B,) arrays; the published values by default): ``std_weight_position`` σ_p = 1/20,
``std_weight_velocity`` σ_v = 1/160, ``std_aspect`` s_a = 1e-2, ``std_aspect_rate`` s_ȧ = 1e-5,
``std_aspect_measurement`` s_m = 1e-1, each within :data:`STD_RANGE`. (ByteTrack's tracker also zeroes vh of a lost
track before predicting it; that is tracker logic outside its ``KalmanFilter`` and not modelled here.)

Gap policy (not ByteTrack's; the defaults are its filter bit for bit): ``gap_velocity_decay`` and ``gap_size_decay``,
per track in [0, 1] (:data:`DECAY_RANGE`), damp the rates of the centre (x, y) and of the size (a, h) in the *output*
inside detection gaps by that factor per second of gap (ρ^τ a frame; 0 holds the coordinate at its last detected
estimate): :mod:`bboxtune.filters.gap_output`. The filter's state, and every estimate on a detected frame, is
unchanged. A tracker's online filter (:class:`bboxtune.filters.box_online.OnlineBoxKF`) refuses them.

Every block [coordinate, rate] of P stays uncoupled from the others (F, H, Q, R and P₀ are all block-diagonal), so
the 8×8 recursion is four 2-state problems whose noise scales with the track's height: :class:`BoxKF` runs them in
closed form, vectorised over tracks and coordinates, with a loop over frames only (the gains depend on the data
through h: no gain sharing). Exact in frame units (``IN_FRAMES``): τ only converts the velocities to units per
second. Output: states (B, T, 8) = (cx, cy, w = a h, h), then their rates per second (ẇ = ȧ h + a ḣ).
``run_from`` continues from a :class:`bboxtune.filters.base.Carry` holding the filter's own state [x, y, a, h, rates per
second] and its block-diagonal covariance.

>>> import numpy as np
>>> from bboxtune import filters
>>> f = filters.make("bytetrack_kf", filters.constant_velocity(1 / 30, ndim=4))
>>> f.run(np.array([[50.0, 60.0, 20.0, 40.0], [np.nan] * 4, [52.0, 61.0, 22.0, 40.0]]))[:, :4].round(2)
array([[50.  , 60.  , 20.  , 40.  ],
       [50.  , 60.  , 20.  , 40.  ],
       [51.85, 60.92, 20.06, 40.  ]])
"""

from __future__ import annotations

from abc import abstractmethod
from functools import cached_property
from typing import Any, ClassVar, cast

import numpy as np

from bboxtune.filters import box_kf_kernels, gap_output, jit
from bboxtune.filters.base import CHUNK_SAMPLES, Carry, Filter, not_started
from bboxtune.filters.blocks import block_diagonal, coordinate_blocks
from bboxtune.filters.box_state import _P, _P00, _P01, _P11, _V, HeightNoise, HeightVariance, initiate, update_state
from bboxtune.filters.model import StateSpaceModel, check_model
from bboxtune.filters.threads import limited_blas
from bboxtune.filters.validation import check_range

M = 4  # measured coordinates of a box
# the gap policy (bboxtune.filters.gap_output): decays per second of gap of the centre's and the size's rates
GAP_DECAYS = ("gap_velocity_decay", "gap_size_decay")
DECAY_RANGE = (0.0, 1.0)
STD_RANGE = (1e-12, 1e12)  # every noise weight or standard deviation of the peer filters (finite over all of it)
SIZE_MIN = 1e-30  # a measured box's width and height at least this (and <= VALUE_MAX, as every y entry)
_HEIGHT = np.array([1.0, 1.0, 0.0, 1.0])  # the coordinates whose noise scales with h: x, y, h
_ASPECT = np.array([0.0, 0.0, 1.0, 0.0])  # the aspect a


def check_std(name: str, value: object) -> np.ndarray:
    """A noise weight or standard deviation within :data:`STD_RANGE` (scalar or (B,))."""
    return check_range(name, value, *STD_RANGE)


def check_boxes(Y: np.ndarray) -> None:
    """Measured boxes (B, T, 4) (cx, cy, w, h): every row wholly NaN (no detection) or finite with w, h >= SIZE_MIN."""
    nan = np.isnan(Y)
    partial = nan.any(axis=-1) & ~nan.all(axis=-1)
    if partial.any():
        b, t = np.argwhere(partial)[0]
        raise ValueError(f"y[{b}, {t}] = {Y[b, t].tolist()} is partly NaN; allowed: a whole box (cx, cy, w, h) or "
                         "a row of NaN (no detection)")
    small = Y[..., 2:] < SIZE_MIN  # False for NaN
    if small.any():
        b, t, k = np.argwhere(small)[0]
        raise ValueError(f"y[{b}, {t}] has {'wh'[k]} = {Y[b, t, 2 + k].item()!r}; allowed: box sizes "
                         f"w, h >= {SIZE_MIN:g}")




class BoxKF(Filter):
    """A Kalman filter of whole boxes in the filter's own coordinates z = :meth:`_measure` (y), four uncoupled
    [coordinate, rate] blocks with dt = 1 frame and :class:`HeightNoise`. Subclasses define the coordinates
    (:meth:`_measure`), the noise (:meth:`_noise`) and the boxes of a state (:meth:`_to_boxes`)."""

    IN_FRAMES: ClassVar[bool] = True
    FIXED: ClassVar[tuple[int, ...]] = ()  # coordinates without a rate (SORT's aspect): rate and its variance 0
    # the recursion runs in bboxtune.filters.box_kf_kernels (unless $BBOXTUNE_JIT=0): only without a _before_predict hook
    COMPILED: ClassVar[bool] = False

    def __init__(self, model: StateSpaceModel, **params: Any) -> None:
        if check_model(model).M != M:
            raise ValueError(f"{self.name} filters boxes (cx, cy, w, h); the model has M={model.M}, allowed: "
                             "bboxtune.filters.constant_velocity(tau, ndim=4)")
        super().__init__(model, **params)

    @abstractmethod
    def _noise(self, params: dict[str, np.ndarray]) -> HeightNoise:
        """The noise of tracks with the per-track parameters ``params`` (arrays (n,))."""

    @abstractmethod
    def _measure(self, Y: np.ndarray) -> np.ndarray:
        """Boxes (T, 4, n) (cx, cy, w, h on axis 1) → the measured coordinates z (T, 4, n)."""

    @abstractmethod
    def _to_boxes(self, S: np.ndarray) -> None:
        """States (…, 4) (the coordinates) or (…, 8) (then their rates per frame) → boxes (cx, cy, w, h) (and their
        rates per frame), in place."""

    def _before_predict(self, X: np.ndarray) -> None:
        """Adjust the state X (5, 4, n) in place before a predict (SORT's area-rate guard); none by default."""

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        return {k: check_std(k, v) for k, v in params.items()}

    def _gap_decay(self, params: dict[str, np.ndarray], n: int) -> np.ndarray | None:
        """The per-frame decays (4, n) of the gap output (:mod:`bboxtune.filters.gap_output`) of tracks with the
        per-track parameters ``params`` (arrays (n,)); None: the filter's own prediction (no gap policy)."""
        return None

    def run(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """States (T, 8) or (B, T, 8) of boxes ``y`` (T, 4) or (B, T, 4), NaN rows = no detection (module docstring)."""
        return self._filter(y, u, None, positions_only=False, carried=False)[0]

    def positions(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The boxes only, (T, 4) or (B, T, 4): ``run(y)[..., :4]`` without computing the rates."""
        return self._filter(y, u, None, positions_only=True, carried=False)[0]

    def run_from(self, y: np.ndarray, carry: Carry | None = None,
                 u: np.ndarray | None = None) -> tuple[np.ndarray, Carry]:
        """As :meth:`bboxtune.filters.base.Filter.run_from`; the carry holds the filter's own state (module docstring)."""
        states, end = self._filter(y, u, carry, positions_only=False, carried=True)
        return states, cast(Carry, end)  # built: carried=True

    @limited_blas
    def _filter(self, y: np.ndarray, u: np.ndarray | None, carry: Carry | None, positions_only: bool,
                carried: bool) -> tuple[np.ndarray, Carry | None]:
        """The states (or boxes only: ``positions_only``) of ``y`` from ``carry``, and the carry after the last frame
        (None unless ``carried``: ``run`` and ``positions`` do not build it)."""
        Y, _, per_track, batched = self._inputs(y, u)
        check_boxes(Y)
        n_tracks, T, _ = Y.shape
        start = None if carry is None else self._start_state(carry, n_tracks)
        missed = np.zeros(n_tracks) if carry is None else np.array(carry.missed)[:, 0]  # frames into a gap at the start
        out = np.empty((n_tracks, T, M if positions_only else 2 * M))
        ends: list[np.ndarray] = []
        step = max(1, CHUNK_SAMPLES // max(1, T * M))  # tracks per chunk: bounded working memory
        for first in range(0, n_tracks if T else 0, step):
            rows = slice(first, min(n_tracks, first + step))
            chunk = {k: v[rows] for k, v in per_track.items()}
            noise, decay = self._noise(chunk), self._gap_decay(chunk, rows.stop - rows.start)
            X = np.full((5, M, rows.stop - rows.start), np.nan) if start is None else start[..., rows].copy()
            O = None if decay is None else gap_output.start(X, missed[rows], decay)
            z = self._measure(Y[rows].transpose(1, 2, 0))  # (T, 4, n)
            began = np.logical_or.accumulate(~np.isnan(z[:, 0]), axis=0) | ~np.isnan(X[_P, 0])  # (T, n)
            means = self._run_boxes(z, noise, X, positions_only, decay, O)  # X: now the state after the last frame
            missed[rows] = gap_output.missed_after(~np.isnan(z[:, 0]), missed[rows], ~np.isnan(X[_P, 0]))
            states = out[rows]  # a view (n, T, 4 or 8): [coordinates, rates]
            states.reshape(-1, T, means.shape[1], M)[...] = means.transpose(3, 0, 1, 2)
            self._to_boxes(states)
            states[..., M:] /= self.model.tau
            self._check_began_finite(states, began, rows)
            ends.append(X)
        if not carried:
            return (out if batched else out[0]), None
        if T == 0:
            end_carry = carry if carry is not None else not_started(n_tracks, M)
        else:
            end_carry = self._carry(np.concatenate(ends, axis=2) if ends else np.empty((5, M, 0)), Y[:, -1], missed)
        return (out if batched else out[0]), end_carry

    def _run_boxes(self, z: np.ndarray, noise: HeightNoise, X: np.ndarray, positions_only: bool,
                   decay: np.ndarray | None = None, O: np.ndarray | None = None) -> np.ndarray:
        """The recursion on measured coordinates ``z`` (T, 4, n) (NaN columns: no detection) from state ``X`` (5, 4, n)
        (NaN for a track waiting for its first detection), updated in place to the state after the last frame.
        Returns the means (T, 2, 4, n) = [p, v] ((T, 1, 4, n) = [p] if ``positions_only``): the filter's, or with
        per-frame gap decays ``decay`` (4, n), the gap output (:mod:`bboxtune.filters.gap_output`) from its state
        ``O`` (2, 4, n), updated in place."""
        T, _, n = z.shape
        P_start, Q = HeightVariance(noise.start, (2, M, n)), HeightVariance(noise.process, (2, M, n))
        R = HeightVariance(noise.measurement, (M, n))
        detected = ~np.isnan(z[:, 0])  # (T, n)
        z = np.where(detected[:, None], z, 0.0)  # 0 where no detection
        gate = detected[:, None].astype(float)  # a missing detection: gain 0 (predict only)
        gated = ~detected.all(axis=1)
        waiting = np.isnan(X[_P, 0]) & detected.any(axis=0)
        first = detected.argmax(axis=0)
        means = np.empty((T, 1 if positions_only else 2, M, n))
        if self.COMPILED and jit.enabled():
            pairs = [np.stack(v.pair) for v in (P_start, Q, R)]
            box_kf_kernels.run_boxes(z, detected, np.where(waiting, first, -1), *pairs,
                                     np.array([v.fixed is not None for v in (P_start, Q, R)]), O is not None,
                                     np.ones((M, n)) if decay is None else decay, X, X[_P:_V + 1] if O is None else O,
                                     means)
            return means
        starts = {int(t): np.flatnonzero(waiting & (first == t)) for t in np.unique(first[waiting])}
        for t in range(T):
            self.predict_state(X, Q)
            update_state(X, z[t], R, gate[t] if gated[t] else None)
            if t in starts:  # initiate: mean [m, 0], P₀ from the detection's height
                rows = starts[t]
                initiate(X, z[t][:, rows], P_start, rows)
            if O is None or decay is None:
                means[t] = X[_P] if positions_only else X[_P:_V + 1]
            else:
                gap_output.step(O, X, detected[t], decay)
                means[t] = O[_P] if positions_only else O
        return means

    def predict_state(self, X: np.ndarray, Q: HeightVariance) -> None:
        """The predict step on state X (5, 4, n), in place (h: the current mean height): x ← F x, P ← F P Fᵀ + Q per
        2×2 block."""
        self._before_predict(X)
        q = Q.at(X[_P, 3])
        P00 = X[_P00]
        P00 += X[_P01]  # P00 + 2 P01 + P11 = P00 + P01 + (P01 + P11)
        X[_P:_P01 + 1:2] += X[_V:_P11 + 1:3]  # p += v, P01 += P11
        P00 += X[_P01]
        X[_P00:] += q  # P00 += q_p, P11 += q_v

    def _check_began_finite(self, states: np.ndarray, began: np.ndarray, rows: slice) -> None:
        """Every state (n, T, k) where a track has ``began`` (T, n) must be finite (it is within the documented ranges:
        a non-finite one is a numerical failure, reported rather than returned)."""
        bad = began.T & ~np.isfinite(states).all(-1)
        if bad.any():
            b, t = np.argwhere(bad)[0]
            raise FloatingPointError(f"{self.name}: non-finite estimate at track {rows.start + b}, frame {t} after its "
                                     f"start (parameters {self.params}): please report this input")

    def _carry(self, X: np.ndarray, y_last: np.ndarray, missed: np.ndarray) -> Carry:
        """The :class:`Carry` of state ``X`` (5, 4, n): x = [coordinates, rates per second], P its 8×8 block-diagonal
        covariance, ``missed`` the frames since each track's last detection (n,) (the gap output continues from it)."""
        tau = self.model.tau
        P01 = X[_P01].T / tau
        blocks = np.stack([np.stack([X[_P00].T, P01], -1), np.stack([P01, X[_P11].T / tau**2], -1)], -2)
        started = ~np.isnan(X[_P, :1].T)
        return Carry(x=np.concatenate([X[_P].T, X[_V].T / tau], axis=1), P=block_diagonal(blocks), y_last=y_last,
                     measured=np.repeat(started, M, axis=1), missed=np.repeat(missed[:, None], M, axis=1))

    def _start_state(self, carry: Carry, n_tracks: int) -> np.ndarray:
        """The state X (5, 4, B) a carry holds, checked against y's batch (ValueError naming the field)."""
        if not isinstance(carry, Carry):
            raise ValueError(f"carry is a {type(carry).__name__}; allowed: None or a bboxtune.filters.base.Carry")
        wants = {"x": (n_tracks, 2 * M), "P": (n_tracks, 2 * M, 2 * M), "y_last": (n_tracks, M),
                 "measured": (n_tracks, M), "missed": (n_tracks, M)}
        for name, want in wants.items():
            shape = getattr(carry, name).shape
            if shape != want:
                raise ValueError(f"carry.{name} has shape {shape}; allowed: {want} (B={n_tracks} tracks of y)")
        if carry.c is not None or carry.P_c is not None:
            raise ValueError(f"carry.c / carry.P_c are given but {self.name} has no camera states; allowed: None")
        if np.isinf(carry.x).any() or np.isinf(carry.P).any():
            raise ValueError("carry.x / carry.P contain ±inf; allowed: finite values (NaN: a track not started)")
        missed = np.asarray(carry.missed)
        if not ((missed >= 0) & (missed == np.round(missed)) & (missed == missed[:, :1])).all():
            raise ValueError("carry.missed: allowed the frames since a track's last detection, an integer >= 0, the "
                             "same for its 4 coordinates")
        blocks = coordinate_blocks(carry.P, M, "carry.P")  # (B, 4, 2, 2)
        waiting = np.isnan(carry.x)
        started = ~waiting.all(axis=1)
        if waiting[started].any() or not np.isfinite(blocks[started]).all():
            raise ValueError(f"carry.x / carry.P: {self.name} starts a track as a whole: a track's state must be "
                             "finite in all 8 entries (with a finite covariance) or NaN in all (not started)")
        fixed = list(self.FIXED)
        if np.any(carry.x[started][:, [M + k for k in fixed]]) or np.any(blocks[started][:, fixed, 1]):
            raise ValueError(f"carry.x / carry.P: {self.name} has no rate for coordinate(s) {fixed}; allowed: that "
                             "rate and its covariance entries 0")
        tau = self.model.tau
        return np.stack([carry.x[:, :M].T, carry.x[:, M:].T * tau, blocks[..., 0, 1].T * tau, blocks[..., 0, 0].T,
                         blocks[..., 1, 1].T * tau**2])


class ByteTrackKF(BoxKF):
    """ByteTrack's / DeepSORT's box Kalman filter (module docstring): parameters ``std_weight_position`` σ_p,
    ``std_weight_velocity`` σ_v, ``std_aspect``, ``std_aspect_rate``, ``std_aspect_measurement``, per track."""

    name: ClassVar[str] = "bytetrack_kf"
    DEFAULTS: ClassVar[dict[str, Any]] = {"std_weight_position": 1 / 20, "std_weight_velocity": 1 / 160,
                                          "std_aspect": 1e-2, "std_aspect_rate": 1e-5, "std_aspect_measurement": 1e-1,
                                          **{k: 1.0 for k in GAP_DECAYS}}
    PER_TRACK: ClassVar[tuple[str, ...]] = tuple(DEFAULTS)
    COMPILED: ClassVar[bool] = True

    @classmethod
    def params_in_frames(cls, params: dict[str, Any], tau: float | np.ndarray) -> dict[str, Any]:
        """The gap decays per second ρ → per frame ρ^τ (the noise weights are per frame already)."""
        return {k: np.asarray(v) ** np.asarray(tau) if k in GAP_DECAYS else v for k, v in params.items()}

    def _validate(self, params: dict[str, Any]) -> dict[str, Any]:
        return {k: check_range(k, v, *DECAY_RANGE) if k in GAP_DECAYS else check_std(k, v) for k, v in params.items()}

    def _gap_decay(self, params: dict[str, np.ndarray], n: int) -> np.ndarray | None:
        velocity, size = (np.broadcast_to(params[k], (n,)) for k in GAP_DECAYS)
        if (velocity == 1.0).all() and (size == 1.0).all():
            return None
        return gap_output.frame_decay(velocity, size, self.model.tau)

    def positions(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """As :meth:`BoxKF.positions`; with the compiled kernels one call of
        :func:`bboxtune.filters.box_kf_kernels.bytetrack_positions` (bit for bit the recursion's boxes, without its
        per-call numpy work: a few µs for the short tracks a tracker's tuner filters, against ~0.3 ms); with a gap
        policy (a decay other than 1) the recursion's. Parameters that are one value for all tracks and float (T, 4) /
        (B, T, 4) boxes go straight to the kernel, which checks the boxes as it reads them; the recursion's checks
        name what a rejected input got wrong."""
        if not jit.enabled():
            return super().positions(y, u)
        shared = self._shared_stds
        if shared is not None and u is None and isinstance(y, np.ndarray) and y.dtype == np.float64 and \
                y.ndim in (2, 3) and y.shape[-1] == M:
            Y = np.ascontiguousarray(y if y.ndim == 3 else y[None])
            out = np.empty(Y.shape)
            if box_kf_kernels.bytetrack_positions(Y, *shared, SIZE_MIN, out):
                return out if y.ndim == 3 else out[0]
            return super().positions(y, u)  # the recursion's error naming the track and frame
        Y, _, per_track, batched = self._inputs(y, u)
        if any((per_track[k] != 1.0).any() for k in GAP_DECAYS):  # a gap policy: the recursion with its gap output
            return super().positions(y, u)
        out = np.empty(Y.shape)
        stds = (per_track[k].astype(float) for k in self.PER_TRACK if k not in GAP_DECAYS)
        if not box_kf_kernels.bytetrack_positions(np.ascontiguousarray(Y), *stds, SIZE_MIN, out):
            return super().positions(y, u)  # the recursion's: it raises the error naming the box or the track and frame
        return out if batched else out[0]

    @cached_property
    def _shared_stds(self) -> tuple[np.ndarray, ...] | None:
        """The noise parameters as (1,) float arrays when each is one value for every track and there is no gap
        policy (the kernel's arguments for any batch); None otherwise."""
        if any(np.ndim(v) for v in self.params.values()) or any(self.params[k] != 1.0 for k in GAP_DECAYS):
            return None
        return tuple(np.array([self.params[k]], dtype=float) for k in self.PER_TRACK if k not in GAP_DECAYS)

    def _noise(self, params: dict[str, np.ndarray]) -> HeightNoise:
        def column(name: str, mask: np.ndarray) -> np.ndarray:  # (4, n): the parameter on the coordinates of mask
            return mask[:, None] * params[name]

        w_p, w_v = column("std_weight_position", _HEIGHT), column("std_weight_velocity", _HEIGHT)
        s_a = np.array([column("std_aspect", _ASPECT), column("std_aspect_rate", _ASPECT)])  # np.stack's, faster
        return HeightNoise(start=(np.array([2 * w_p, 10 * w_v]), s_a), process=(np.array([w_p, w_v]), s_a),
                           measurement=(w_p, column("std_aspect_measurement", _ASPECT)))

    def _measure(self, Y: np.ndarray) -> np.ndarray:
        z = Y.copy()  # (x, y, a, h)
        z[:, 2] = Y[:, 2] / Y[:, 3]
        return z

    def _to_boxes(self, S: np.ndarray) -> None:
        a, h = S[..., 2].copy(), S[..., 3]
        if S.shape[-1] > M:
            S[..., 6] = S[..., 6] * h + a * S[..., 7]  # ẇ = ȧ h + a ḣ
        S[..., 2] = a * h
