"""Batched Kalman recursions shared by ``kf`` and ``kf_cmn`` (one two-state coordinate per channel).

The gain of a linear Kalman filter does not depend on the data, only on the model, the noise parameters,
the prior covariance and which frames have a measurement. So the covariance recursion runs once per *unique*
(parameters, prior covariance, frame-kind sequence) "row", vectorised over rows, and stops as soon as every
row has reached its steady state (the posterior covariance repeats bit for bit and no frame kind changes
later). Each frame's predict + update is then one affine map per channel,

    x_n = M_n x_{n-1} + g_n m_n,                     M_n = (I − K_n D_n) A_n,  g_n = (I − K_n D_n) Λ_n + K_n

(from x⁻ = A x_{n-1} + Λ m_n and x_n = x⁻ + K (m_n − D x⁻), K = (P⁻ Dᵀ + M) S⁻¹ with M the covariance of
the predict's noise with the measurement noise: 0 but for KF-CMN across gaps), applied to all channels at once; only
the time loop is Python — for a few rows (tunings) a loop over blocks of 16 frames, each one matrix product
(:func:`_affine_blocks`). ``m_n`` is the scalar measurement a frame uses (``y_n``, or for KF-CMN
``z_n = y_n − ψ^{g+1} y_m``, y_m the last finite measurement, g frames missing between), ``D`` its observation row,
``A``/``Λ`` the (de-correlated) transition and input gain.

Frame kinds (per channel and frame):

* ``WAIT``   — no prior given and no finite measurement yet: output NaN.
* ``INIT``   — first finite measurement without a prior: x = [y_n, 0], P = the start covariance.
* ``PREDICT``— no usable measurement: x = F x, P = F P Fᵀ + Q (missing data).
* ``UPDATE_Y``— predict, then a standard update on y_n (D = H).
* ``UPDATE_Z``— KF-CMN: de-correlated predict + update on the differenced z_n ([Shmaliy-CMN] Algorithm 1).
* ``UPDATE_Z + i`` — KF-CMN after the i-th gap length of the call (:func:`bboxtune.filters.kf_cmn.differenced_kinds`):
  predict, then the time-correlated update (M ≠ 0) on z_n = y_n − ψ^{g+1} y_m. The kind axis of
  :class:`StepTables` has an entry per kind; kinds are int8 (int32 beyond 123 gap lengths in one call).

A continued run (:meth:`bboxtune.filters.base.Filter.run_from`) starts a channel from its carried posterior state and
covariance (a prior for frame 0) and hands back the covariance at the last frame: the last P of its row's
recursion, or the steady P where the recursion stopped early, so the carry adds no per-frame work.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, cast

import numpy as np

from bboxtune.filters import jit, kalman_kernels
from bboxtune.filters.base import AxisCarry
from bboxtune.filters.blocks import split_covariance, split_state

WAIT, INIT, PREDICT, UPDATE_Y, UPDATE_Z = range(5)  # UPDATE_Z + i: KF-CMN over the i-th gap length

# Without a prior, the velocity starts at 0 with std VELOCITY_PRIOR_SCALE · σ_pos / τ: a million times the
# variance of the two-point velocity estimate, so the second measurement fixes the velocity (prior weight
# < 2e-6) while the covariance stays well inside float64 range.
VELOCITY_PRIOR_SCALE = 1e3

# Up to this many rows, apply_affine runs each row in blocks of frames (~0.25 ms per row of 500 frames);
# beyond, one frame-by-frame loop for all channels (~3 ms per 500 frames whatever the number of rows) is cheaper.
BLOCK_ROWS = 8


@dataclass(frozen=True)
class StepTables:
    """Per frame kind and row (kind first, row G last): x⁻ = A x + Λ m, update with row D, variance R, and the
    covariance M of the predict's noise with the measurement noise (the time-correlated form)."""

    A: np.ndarray  # (kinds, 2, 2, G) transition used by the predict
    Q: np.ndarray  # (kinds, 2, 2, G) process noise covariance of that predict
    Lam: np.ndarray  # (kinds, 2, G) input gain on the measurement (Λ of [Shmaliy-CMN] eq. 10; 0 for a plain KF)
    D: np.ndarray  # (kinds, 2, G) observation row (0 for PREDICT: gain 0, covariance unchanged)
    R: np.ndarray  # (kinds, G) measurement noise variance (1 where unused)
    M: np.ndarray  # (kinds, 2, G) noise cross-covariance (filterpy ``update_correlated``'s M; 0 but KF-CMN's gaps)


def plain_tables(F: np.ndarray, Q: np.ndarray, R_y: np.ndarray, H: np.ndarray,
                 n_kinds: int = UPDATE_Z) -> StepTables:
    """Tables of ``n_kinds`` kinds for a standard KF: every kind predicts with (F, Q) (Λ = 0, M = 0); UPDATE_Y
    updates with (H, R_y), the others not (D = 0) until a caller (KF-CMN: its UPDATE_Z kinds) fills them in.
    ``Q`` (2, 2, G), ``R_y`` (G,)."""
    G = len(R_y)
    A = np.broadcast_to(F[:, :, None], (n_kinds, 2, 2, G)).copy()
    Qk = np.broadcast_to(Q, (n_kinds, 2, 2, G)).copy()
    D = np.zeros((n_kinds, 2, G))
    D[UPDATE_Y] = H[:, None]
    R = np.ones((n_kinds, G))
    R[UPDATE_Y] = R_y
    return StepTables(A=A, Q=Qk, Lam=np.zeros((n_kinds, 2, G)), D=D, R=R, M=np.zeros((n_kinds, 2, G)))


def frame_kinds(finite: np.ndarray, prior: bool | np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
    """Kind of every frame (C, T), int8, from the finite-measurement mask (C, T).

    The first finite measurement is a standard update (``prior``, bool or per channel (C,)) or the
    initialisation (no prior); later finite frames update on y (KF-CMN turns those with an earlier finite y into
    UPDATE_Z kinds: :func:`bboxtune.filters.kf_cmn.differenced_kinds`). A continued run (``Filter.run_from``) passes
    ``measured`` (C,): channels whose first finite measurement lies before frame 0. Compiled where
    :func:`bboxtune.filters.jit.enabled` (:mod:`bboxtune.filters.kalman_kernels`), else :func:`frame_kinds_numpy`."""
    if jit.enabled():
        return kalman_kernels.frame_kinds(finite, prior, measured)
    return frame_kinds_numpy(finite, prior, measured)


def frame_kinds_numpy(finite: np.ndarray, prior: bool | np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
    """:func:`frame_kinds` in numpy (the reference)."""
    C, T = finite.shape
    frames = np.arange(T)
    first_index = np.where(finite.any(axis=1), np.argmax(finite, axis=1), T)
    if measured is not None:
        first_index = np.where(measured, -1, first_index)
    first = frames == first_index[:, None]
    kinds = np.full(finite.shape, PREDICT, dtype=np.int8)
    kinds[finite & ~first] = UPDATE_Y
    prior = np.broadcast_to(prior, (C,))[:, None]
    kinds[first & prior] = UPDATE_Y
    kinds[first & ~prior] = INIT
    kinds[(frames < first_index[:, None]) & ~prior] = WAIT
    return kinds


def channel_start(x0: np.ndarray | None, P0: np.ndarray | None, M: int, n_channels: int, var_position: np.ndarray,
                  tau: float, carry: AxisCarry | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start state (C, 2) and covariance (C, 2, 2) of every channel (channel c = coordinate c % M), and
    which channels start from a prior (C,) bool: ``x0`` or a carried state.

    ``x0``/``P0`` are full-model (K,)/(K, K) arrays or None. The covariance is that of the prior x0 when x0
    is given, else that of the state initialised from the first finite measurement. ``P0=None`` →
    diag(var_position, (VELOCITY_PRIOR_SCALE² · var_position / τ²)) per channel. Channels whose ``carry``
    state is finite start from it instead (the others have not started: they start as above)."""
    coord = np.arange(n_channels) % M
    x_start = np.zeros((n_channels, 2)) if x0 is None else split_state(x0, M)[coord]
    if P0 is None:
        P_start = np.zeros((n_channels, 2, 2))
        P_start[:, 0, 0] = var_position
        P_start[:, 1, 1] = VELOCITY_PRIOR_SCALE**2 * var_position / tau**2
    else:
        P_start = split_covariance(P0, M)[coord]
    if carry is None:
        return x_start, P_start, np.full(n_channels, x0 is not None)
    carried = ~np.isnan(carry.x[:, 0])
    x_start[carried] = carry.x[carried]
    P_start[carried] = carry.P[carried]
    return x_start, P_start, carried | (x0 is not None)


def gain_recursion(kinds: np.ndarray, tables: StepTables,
                   P_start: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
    """Affine coefficients (T, 6, G) = [M00, M01, M10, M11, g0, g1] of every row and frame, the frame
    from which every row's coefficients stay constant (T if they never settle), and the posterior covariance
    (2, 2, G) at the last frame (at an early stop: the steady one, which every later frame repeats).

    ``kinds`` (G, T), ``P_start`` (2, 2, G): the prior before frame 0 (PREDICT/UPDATE kinds) and the
    covariance at WAIT/INIT frames. Each frame is :func:`joseph_step` on arrays of the G rows (one row: on Python
    floats, several times faster than numpy calls on length-1 arrays — the env filters one parameter set at a
    time). Stops early once all rows are in steady state (P_n = P_{n−1} bit for bit, no kind change later)."""
    G, T = kinds.shape
    n_kinds = len(tables.R)
    flat = np.concatenate([tables.A.reshape(n_kinds, 4, G), tables.Q.reshape(n_kinds, 4, G), tables.Lam, tables.D,
                           tables.R[:, None]], axis=1)  # (kind, 13 entries, row)
    correlated = np.any(tables.M != 0.0, axis=(1, 2))  # kinds with a noise cross-covariance (KF-CMN's gaps)
    coef = np.empty((T, 6, G))
    settled = np.all(kinds == kinds[:, -1:], axis=1)
    settled_from = np.where(settled, 0, T - np.argmax(kinds[:, ::-1] != kinds[:, -1:], axis=1)).max()
    start: tuple[Any, ...] = tuple(P_start.reshape(4, G))  # rows of P_start (4 × (G,)), or 4 floats below
    if G == 1:  # Python floats
        table = [tuple(entries) for entries in flat[:, :, 0].tolist()]
        cross = [tuple(M) if c else None for M, c in zip(tables.M[:, :, 0].tolist(), correlated, strict=False)]
        start, kinds_n, rows = tuple(float(v[0]) for v in start), kinds[0].tolist(), None
    else:
        uniform = np.all(kinds == kinds[:1], axis=0)  # frames where every row has the same kind
        with_cross = np.any(correlated[kinds], axis=0)  # frames where some row has a cross-covariance
        resets = np.any(kinds <= INIT, axis=0)  # frames where some row waits or initialises
        rows = np.arange(G)
    P = start
    for n in range(T):
        if rows is None:
            k = kinds_n[n]
            P_new, row = joseph_step(table[k], P, cross[k])
            if k <= INIT:  # WAIT / INIT: x = [m, 0] (INIT) or 0 (WAIT), covariance back to the start one
                P_new, row = start, (0.0, 0.0, 0.0, 0.0, 1.0 if k == INIT else 0.0, 0.0)
            coef[n, :, 0] = row
        else:
            k = kinds[:, n]
            M = tuple(tables.M[k[0]] if uniform[n] else tables.M[k, :, rows].T) if with_cross[n] else None
            P_new, row = joseph_step(tuple(flat[k[0]] if uniform[n] else flat[k, :, rows].T), P, M)
            coef[n] = row
            if resets[n]:
                reset = k <= INIT
                P_new = tuple(np.where(reset, s0, p) for s0, p in zip(start, P_new, strict=False))
                coef[n][:, reset] = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0])[:, None]  # x = [m, 0] (INIT)
                coef[n][4, k == WAIT] = 0.0  # x = 0 (WAIT; output NaN)
        # P_n = P_{n-1} and no kind changes later: every later frame repeats frame n
        if n % 8 == 7 and n >= settled_from and all(np.array_equal(a, b) for a, b in zip(P_new, P, strict=False)):
            coef[n + 1:] = coef[n]
            return coef, n, np.reshape(np.array(P_new), (2, 2, G))
        P = P_new
    return coef, T, np.reshape(np.array(P), (2, 2, G))


def joseph_step(t: tuple, P: tuple, M: tuple | None = None) -> tuple[tuple, tuple]:
    """One frame of [Shmaliy-CMN] Algorithm 1 on the entries of 2×2 matrices (Python floats or arrays over rows):
    table entries ``t`` = (A row-major, Q row-major, Λ, D, R) and the previous posterior ``P`` (row-major) →
    the new posterior (Joseph form) and the affine coefficients [(I − K D) A row-major, g = (I − K D) Λ + K].
    ``M`` = (M0, M1), the covariance of the predict's noise with the measurement noise, makes it the time-correlated
    update (KF-CMN across a gap: docs/notes/kf-cmn-gaps.md, eqs. G6–G7); None: 0 (no extra work)."""
    a00, a01, a10, a11, q00, q01, q10, q11, l0, l1, d0, d1, r = t
    p00, p01, p10, p11 = P
    # P⁻ = A P Aᵀ + Q (Alg. 1 line 5)
    m00 = (a00 * p00 * a00 + a00 * p01 * a01) + (a01 * p10 * a00 + a01 * p11 * a01) + q00
    m01 = (a00 * p00 * a10 + a00 * p01 * a11) + (a01 * p10 * a10 + a01 * p11 * a11) + q01
    m10 = (a10 * p00 * a00 + a10 * p01 * a01) + (a11 * p10 * a00 + a11 * p11 * a01) + q10
    m11 = (a10 * p00 * a10 + a10 * p01 * a11) + (a11 * p10 * a10 + a11 * p11 * a11) + q11
    pd0, pd1 = m00 * d0 + m01 * d1, m10 * d0 + m11 * d1
    if M is None:
        S = d0 * pd0 + d1 * pd1 + r  # S = D P⁻ Dᵀ + R (line 6)
        k0, k1 = pd0 / S, pd1 / S  # K = P⁻ Dᵀ S⁻¹ (line 7)
    else:
        c0, c1 = M
        S = d0 * pd0 + d1 * pd1 + 2.0 * (d0 * c0 + d1 * c1) + r  # S = D P⁻ Dᵀ + D M + Mᵀ Dᵀ + R (G6)
        k0, k1 = (pd0 + c0) / S, (pd1 + c1) / S  # K = (P⁻ Dᵀ + M) S⁻¹ (G6)
    i00, i01, i10, i11 = 1.0 - k0 * d0, 0.0 - k0 * d1, 0.0 - k1 * d0, 1.0 - k1 * d1  # I − K D
    # Joseph form (I − KD) P⁻ (I − KD)ᵀ + K R Kᵀ (= line 10 for the optimal K)
    n00 = (i00 * m00 * i00 + i00 * m01 * i01) + (i01 * m10 * i00 + i01 * m11 * i01) + r * k0 * k0
    n01 = (i00 * m00 * i10 + i00 * m01 * i11) + (i01 * m10 * i10 + i01 * m11 * i11) + r * k0 * k1
    n10 = (i10 * m00 * i00 + i10 * m01 * i01) + (i11 * m10 * i00 + i11 * m11 * i01) + r * k1 * k0
    n11 = (i10 * m00 * i10 + i10 * m01 * i11) + (i11 * m10 * i10 + i11 * m11 * i11) + r * k1 * k1
    if M is not None:  # − (I − KD) M Kᵀ − K Mᵀ (I − KD)ᵀ (G7)
        u0, u1 = i00 * c0 + i01 * c1, i10 * c0 + i11 * c1
        n00, n01 = n00 - 2.0 * u0 * k0, n01 - (u0 * k1 + k0 * u1)
        n10, n11 = n10 - (u1 * k0 + k1 * u0), n11 - 2.0 * u1 * k1
    row = (i00 * a00 + i01 * a10, i00 * a01 + i01 * a11, i10 * a00 + i11 * a10, i10 * a01 + i11 * a11,
           i00 * l0 + i01 * l1 + k0, i10 * l0 + i11 * l1 + k1)
    return (n00, n01, n10, n11), row


def apply_affine(coef: np.ndarray, steady_from: int, row_of_channel: np.ndarray, m: np.ndarray,
                 x_start: np.ndarray) -> np.ndarray:
    """Run x_n = M_n x_{n-1} + g_n m_n for every channel: ``coef`` (T, 6, G) constant from frame
    ``steady_from`` on, ``m`` (C, T) with 0 where a frame has no measurement, ``x_start`` (C, 2).
    Returns (C, T, 2). With few rows (G <= ``BLOCK_ROWS``) each row's channels run in blocks of frames
    (:func:`_affine_blocks`), otherwise frame by frame for all channels at once."""
    C, T = m.shape
    G = coef.shape[2]
    m_t = np.ascontiguousarray(m.T)
    if G <= BLOCK_ROWS:
        states = np.empty((C, T, 2))
        for g in range(G):  # rows (distinct tunings), not time
            channels = np.flatnonzero(row_of_channel == g)
            states[channels] = _affine_blocks(coef[:, :, g], x_start[channels].T, m_t[:, channels]).transpose(2, 0, 1)
        return states
    out = np.empty((T, 2, C))
    p, v = x_start[:, 0], x_start[:, 1]
    steady = coef[min(steady_from, T - 1)].take(row_of_channel, axis=1)
    for n in range(T):
        c = coef[n].take(row_of_channel, axis=1) if n < steady_from else steady
        p, v = c[0] * p + c[1] * v + c[4] * m_t[n], c[2] * p + c[3] * v + c[5] * m_t[n]
        out[n, 0] = p
        out[n, 1] = v
    return out.transpose(2, 0, 1)


def _affine_blocks(coef: np.ndarray, x_prev: np.ndarray, m: np.ndarray, block: int = 16,
                   group: int = 4096) -> np.ndarray:
    """x_n = M_n x_{n-1} + g_n m_n for all channels, with ``coef`` (T, 6) rows [M (row-major), g] shared by
    them, ``block`` frames per matrix product: within a block starting at frame b,
    x_{b+i} = Φ_i x_{b-1} + Σ_{j<=i} Ψ_ij m_{b+j} with Φ_i = M_{b+i}⋯M_b and Ψ_ij = M_{b+i}⋯M_{b+j+1} g_{b+j}
    (Φ, Ψ of ``group`` blocks built together — 16 MB —, a loop over the ``block`` offsets). ``x_prev`` (2, C) the
    state before frame 0, ``m`` (T, C) → (T, 2, C)."""
    T, C = m.shape
    L = min(block, T)
    out = np.empty((T, 2, C))
    for first in range(0, T, L * group):  # groups of blocks: bounded memory for long tracks
        last = min(T, first + L * group)
        out[first:last] = _affine_block_group(coef[first:last], x_prev, m[first:last], L)
        x_prev = out[last - 1]
    return out


def _affine_block_group(coef: np.ndarray, x_prev: np.ndarray, m: np.ndarray, L: int) -> np.ndarray:
    """:func:`_affine_blocks` on consecutive blocks of ``L`` frames, all built at once."""
    T, C = m.shape
    nb = -(-T // L)
    pad = nb * L - T  # trailing frames with M = 0, g = 0: their outputs are dropped
    coef = np.concatenate([coef, np.zeros((pad, 6))]) if pad else coef
    M, g = coef[:, :4].reshape(nb, L, 2, 2), coef[:, 4:].reshape(nb, L, 2)
    Phi = np.empty((nb, L, 2, 2))
    Psi = np.zeros((nb, L, L, 2))  # [block, i, j]
    Phi[:, 0], Psi[:, 0, 0] = M[:, 0], g[:, 0]
    for i in range(1, L):  # offsets within a block, not time
        Phi[:, i] = M[:, i] @ Phi[:, i - 1]
        Psi[:, i, :i] = np.einsum("bkl,bjl->bjk", M[:, i], Psi[:, i - 1, :i])
        Psi[:, i, i] = g[:, i]
    propagate = Phi.reshape(nb, 2 * L, 2)  # row (i, component)
    drive = Psi.transpose(0, 1, 3, 2).reshape(nb, 2 * L, L)  # row (i, component), column j
    m = np.concatenate([m, np.zeros((pad, C))]) if pad else m
    out = np.empty((nb * L, 2, C))
    for b in range(nb):  # blocks of frames, in order
        out[b * L:(b + 1) * L] = (propagate[b] @ x_prev + drive[b] @ m[b * L:(b + 1) * L]).reshape(L, 2, C)
        x_prev = out[(b + 1) * L - 1]
    return out[:T]


def _group_rows(key: np.ndarray, kinds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Channels with equal ``key`` (C, k) uint64 columns and equal ``kinds`` (C, T) share one row.

    Returns (index of one channel per row (G,), row of every channel (C,)). Kind sequences are compared
    through a 64-bit polynomial hash, then checked exactly (falling back to exact grouping on a collision)."""
    C, T = kinds.shape
    if (kinds == kinds[:1]).all():
        if C and (key == key[:1]).all():  # one row (a track without gaps, one parameter set): what the sort below gives
            return np.zeros(1, dtype=np.intp), np.zeros(C, dtype=np.intp)
        hashed = np.zeros(C, dtype=np.uint64)  # one kind sequence for all channels (the usual case)
    else:
        weights = np.random.default_rng(0).integers(1, 2**63, size=T, dtype=np.uint64) | np.uint64(1)
        with np.errstate(over="ignore"):
            hashed = (kinds.astype(np.uint64) * weights).sum(axis=1, dtype=np.uint64)
    cols = np.concatenate([key, hashed[:, None]], axis=1)
    order = np.lexsort(cols.T[::-1])
    ordered = cols[order]
    new_row = np.r_[True, np.any(ordered[1:] != ordered[:-1], axis=1)]
    row_of_channel = np.empty(C, dtype=np.intp)
    row_of_channel[order] = np.cumsum(new_row) - 1
    first_of_row = order[new_row]
    if not np.array_equal(kinds, kinds[first_of_row][row_of_channel]):  # hash collision: exact grouping
        exact = np.concatenate([key.view(np.uint8), kinds.view(np.uint8)], axis=1)
        _, first_of_row, row_of_channel = np.unique(exact, axis=0, return_index=True, return_inverse=True)
        row_of_channel = row_of_channel.ravel()
    return first_of_row, row_of_channel


GainRecursion = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, int, np.ndarray]]


def filter_channels(m: np.ndarray, kinds: np.ndarray, row_params: np.ndarray, x_start: np.ndarray,
                    P_start: np.ndarray, build_tables: Callable[[np.ndarray], StepTables] | None = None,
                    recursion: GainRecursion | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Filter channels (C, T) that share one model up to their parameters.

    ``row_params`` (C, n): the per-channel parameters the gains depend on. Either ``build_tables(params (G, n))``
    returns the :class:`StepTables` of G unique rows (for :func:`gain_recursion`), or ``recursion(kinds (G, T),
    params (G, n), P_start (2, 2, G))`` computes their coefficients as :func:`gain_recursion` does (the UKF's
    sigma-point recursion). Channels with equal parameters, start covariance and frame kinds share one gain
    sequence (compiled kernels: :mod:`bboxtune.filters.kalman_kernels`). Returns posterior states (C, T, 2), NaN at
    WAIT frames, and the posterior covariance at the last frame (C, 2, 2), NaN for channels still waiting there."""
    C, T = m.shape
    if T == 1:  # one frame (a tracker's step): a row per channel costs less than finding the shared ones
        first_of_row = row_of_channel = np.arange(C)
    else:
        key = np.concatenate([row_params.reshape(C, -1), P_start.reshape(C, 4)], axis=1)
        first_of_row, row_of_channel = _group_rows(np.ascontiguousarray(key).view(np.uint64), kinds)
    compiled = jit.enabled()  # the kernels of kalman_kernels, else the numpy references here
    if recursion is None:
        tables_of = cast("Callable[[np.ndarray], StepTables]", build_tables)  # given where recursion is not
        gains = kalman_kernels.gain_recursion if compiled else gain_recursion
        recursion = lambda k, p, P: gains(k, tables_of(p), P)  # noqa: E731
    coef, steady_from, P_rows = recursion(kinds[first_of_row], row_params[first_of_row],
                                          P_start[first_of_row].transpose(1, 2, 0))
    states = (kalman_kernels.apply_affine if compiled else apply_affine)(coef, steady_from, row_of_channel, m, x_start)
    P_end = P_rows[:, :, row_of_channel].transpose(2, 0, 1)
    if np.any(kinds[:, 0] == WAIT):  # WAIT frames lead a channel's sequence
        states[kinds == WAIT] = np.nan
        P_end[kinds[:, -1] == WAIT] = np.nan
    return states, P_end


class FramePrior:
    """Mixin of the Kalman back ends that run exactly in frame units (``IN_FRAMES``): besides σ_w → σ_w τ²
    (:meth:`bboxtune.filters.base.Filter.params_in_frames`), the prior ``x0`` (K,) / ``P0`` (K, K) of the state
    [positions, velocities] becomes that of [positions, velocities τ]; one prior serves all tracks, so ``tau``
    must then be a scalar."""

    IN_FRAMES: ClassVar[bool] = True

    @classmethod
    def params_in_frames(cls, params: dict[str, Any], tau: float | np.ndarray) -> dict[str, Any]:
        out = super().params_in_frames(params, tau)  # type: ignore[misc]
        x0, P0 = out.get("x0"), out.get("P0")
        if x0 is None and P0 is None:
            return out
        if np.ndim(tau) != 0:
            raise ValueError(f"tau has shape {np.shape(tau)} but x0/P0 is one prior for all tracks; allowed: a scalar tau")
        K = len(x0) if x0 is not None else len(P0)
        scale = np.concatenate([np.ones(K // 2), np.full(K // 2, float(tau))])
        if x0 is not None:
            out["x0"] = np.asarray(x0, dtype=float) * scale
        if P0 is not None:
            out["P0"] = np.asarray(P0, dtype=float) * np.outer(scale, scale)
        return out
