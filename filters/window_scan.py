"""Kalman estimates on many sliding windows at once, in O(frames) work whatever the window length.

A window filter (OUFIR, OFIR, Kwon's FIR) estimates x_n from the samples of one window by a KF started at the
window's beginning. Run on every window separately that costs O(L) steps per output (L = window length); with
missing samples, where no fixed kernel applies, that was the whole cost of these back ends. Here the KF over a
window is composed from per-frame *elements* with the associative operator of the parallel-in-time Kalman filter
(Särkkä & García-Fernández, "Temporal parallelization of Bayesian smoothers", IEEE TAC 2021, Lemmas 7–8). The
element of frame k (transition from x_{k−1}, measurement y_k, R = 1 — the data are scaled by σ_v) is

    p(x_k | x_{k−1}, y_k) = N(A x_{k−1} + b, C),      p(y_k | x_{k−1}) ∝ exp(−½ x_{k−1}ᵀ J x_{k−1} + ηᵀ x_{k−1})

with S = H Q Hᵀ + 1, K = Q Hᵀ / S: A = (I − K H) F, b = K y_k, C = (I − K H) Q, η = Fᵀ Hᵀ y_k / S,
J = Fᵀ Hᵀ H F / S; a missing y_k gives A = F, b = 0, C = Q, η = 0, J = 0. Composing a_i then a_j::

    M = (I + C_i J_j)⁻¹,   A = A_j M A_i,   b = A_j M (b_i + C_i η_j) + b_j,   C = A_j M C_i A_jᵀ + C_j,
    η = A_iᵀ Mᵀ (η_j − J_j b_i) + η_i,   J = A_iᵀ Mᵀ J_j A_i + J_i.

The composition over frames lo … n maps x_{lo−1} to x_n and carries the likelihood of the window's samples as a
function of x_{lo−1}. With a flat prior on x_{lo−1} (OUFIR: unbiased, no prior) the estimate is
``A J⁻¹ η + b``; with a prior N(μ, P0) on x_{lo−1} (OFIR: its horizon-start prior) it is
``A (μ + P0 (I + J P0)⁻¹ (η − J μ)) + b`` — the same estimates as the KF run over the window, to rounding.

Every channel's frames are cut into blocks of its window length L (frames jL … jL + L − 1); within each block
the prefix compositions (block start … t) and suffix compositions (t … block end) are built by a loop over the L
offsets, vectorised over all blocks and channels. A window [lo, n] of at most L frames is then one suffix (from
lo) composed with one prefix (up to n), or a single prefix (lo at a block start) or suffix (n at a block end); a
window inside one block touching neither end (possible only when a window starts after the frame L − 1 before n)
is reported back to the caller.

A, C and J depend on the missing frames and q only, b and η are linear in the samples: channels that share those
(the coordinates of a box track, missed as whole boxes) are composed once, their b and η side by side
(:class:`Elements`) — about half the work per channel for four coordinates.
"""

from __future__ import annotations

from typing import cast

import numpy as np

PIECE = 8192  # elements per call of combine outside the scans (its ~60 temporaries then stay in cache)

# component rows of an element (14 rows): A (row-major), b, C and J (symmetric: 00, 01, 11), η
A00, A01, A10, A11, B0_, B1_, C00, C01, C11, E0, E1, J00, J01, J11 = range(14)
STRUCTURE = (A00, A01, A10, A11, C00, C01, C11, J00, J01, J11)  # depend on the missing frames and q only
DATA = (B0_, B1_, E0, E1)  # linear in the samples y
_SLOT = {**{row: (0, i) for i, row in enumerate(STRUCTURE)}, **{row: (1, i) for i, row in enumerate(DATA)}}


class Elements:
    """Elements or compositions of n frames: the structure rows A, C, J (10, n) and the data rows b, η (4, …, n).
    Channels with the same missing frames and noise ratio share A, C and J; their b and η ride along the leading
    data axes (e.g. (4, k, n) for k such channels), so the structure is composed once for all of them. Rows are
    read and written by the row constants (``g[A00]``), and unpacking yields the 14 rows in order."""

    def __init__(self, structure: np.ndarray, data: np.ndarray) -> None:
        self.parts = (structure, data)

    @classmethod
    def empty(cls, n: int, lead: tuple[int, ...] = ()) -> Elements:
        return cls(np.empty((len(STRUCTURE), n)), np.empty((len(DATA), *lead, n)))

    @classmethod
    def of(cls, rows: np.ndarray) -> Elements:
        """From one array (14, n) of rows (data without leading axes)."""
        return cls(rows[list(STRUCTURE)], rows[list(DATA)])

    def array(self) -> np.ndarray:
        """The rows as one array (14, n) (data without leading axes)."""
        return np.stack(list(self))

    def __getitem__(self, row: int) -> np.ndarray:
        part, i = _SLOT[row]
        return self.parts[part][i]

    def __setitem__(self, row: int, value: np.ndarray | float) -> None:
        part, i = _SLOT[row]
        self.parts[part][i] = value

    def __iter__(self):  # noqa: ANN204
        return (self[row] for row in range(14))

    def cols(self, at: slice) -> Elements:
        """A view of the frames ``at``."""
        return Elements(self.parts[0][:, at], self.parts[1][..., at])

    def take(self, index: np.ndarray) -> Elements:
        """The frames ``index`` (copies; np.take: ~2× faster than fancy indexing)."""
        return Elements(np.take(self.parts[0], index, axis=1, mode="clip"),
                        np.take(self.parts[1], index, axis=-1, mode="clip"))


class FrameModel:
    """A frame's element in terms of four scalars per frame: with Q = q B Bᵀ (rank one) and f = H F (the first row
    of F), S = q B_0² + 1, w = 1/S, c = q/S, β = q B_0/S for a measured frame (w = β = 0, c = q for a missing one):

        A = F − β B f,   b = β y B,   C = c B Bᵀ,   η = w y fᵀ,   J = w fᵀ f.

    ``F`` (2, 2), ``B`` (2,) of the axis model; ``q`` (E,) = (σ_w/σ_v)², ``y`` (…, E) scaled by σ_v (leading axes:
    channels sharing ``valid`` and q), ``valid`` (E,)."""

    def __init__(self, F: np.ndarray, B: np.ndarray, q: np.ndarray, y: np.ndarray, valid: np.ndarray) -> None:
        self.F, self.B, self.f = F.tolist(), B.tolist(), F[0].tolist()
        S = q * B[0] ** 2 + 1.0
        self.w = np.where(valid, 1.0 / S, 0.0)
        self.c = np.where(valid, q / S, q)
        self.beta = np.where(valid, q * B[0] / S, 0.0)
        self.y = np.where(valid, y, 0.0)

    def elements(self, at: slice, out: Elements) -> None:
        """The elements of frames ``at`` into ``out``."""
        (F00, F01), (F10, F11) = self.F
        B0, B1 = self.B
        f0, f1 = self.f
        w, c, beta, y = self.w[at], self.c[at], self.beta[at], self.y[..., at]
        out[A00], out[A01], out[A10], out[A11] = F00 - beta * B0 * f0, F01 - beta * B0 * f1, F10 - beta * B1 * f0, \
            F11 - beta * B1 * f1
        out[B0_], out[B1_] = beta * y * B0, beta * y * B1
        out[C00], out[C01], out[C11] = c * B0 * B0, c * B0 * B1, c * B1 * B1
        out[E0], out[E1] = w * y * f0, w * y * f1
        out[J00], out[J01], out[J11] = w * f0 * f0, w * f0 * f1, w * f1 * f1

    def append(self, g: Elements, at: slice, out: Elements) -> None:
        """``g`` (n frames) then the single frames ``at``, into ``out``: :func:`combine` with J_j = w fᵀf of rank
        one, so (I + C_g J_j)⁻¹ = I − (w/σ) u f with u = C_g fᵀ, σ = 1 + w f u (Sherman–Morrison) — a KF update of the
        composition, then its predict."""
        (F00, F01), (F10, F11) = self.F
        B0, B1 = self.B
        f0, f1 = self.f
        w, c, beta, y = self.w[at], self.c[at], self.beta[at], self.y[..., at]
        a00, a01, a10, a11, b0, b1, c00, c01, c11, h0, h1, j00, j01, j11 = g
        u0, u1 = c00 * f0 + c01 * f1, c01 * f0 + c11 * f1  # C_g fᵀ
        v0, v1 = f0 * a00 + f1 * a10, f0 * a01 + f1 * a11  # f A_g
        k = w / (1.0 + w * (f0 * u0 + f1 * u1))  # w/σ
        eps = k * (y - (f0 * b0 + f1 * b1))
        m0, m1 = b0 + eps * u0, b1 + eps * u1  # M (b_g + C_g η_j)
        p00, p01, p10, p11 = a00 - k * u0 * v0, a01 - k * u0 * v1, a10 - k * u1 * v0, a11 - k * u1 * v1  # M A_g
        d00, d01, d11 = c00 - k * u0 * u0, c01 - k * u0 * u1, c11 - k * u1 * u1  # M C_g
        e00, e01, e10, e11 = F00 - beta * B0 * f0, F01 - beta * B0 * f1, F10 - beta * B1 * f0, F11 - beta * B1 * f1
        out[A00], out[A01] = e00 * p00 + e01 * p10, e00 * p01 + e01 * p11
        out[A10], out[A11] = e10 * p00 + e11 * p10, e10 * p01 + e11 * p11
        out[B0_], out[B1_] = e00 * m0 + e01 * m1 + beta * y * B0, e10 * m0 + e11 * m1 + beta * y * B1
        s00, s01, s10, s11 = e00 * d00 + e01 * d01, e00 * d01 + e01 * d11, e10 * d00 + e11 * d01, e10 * d01 + e11 * d11
        out[C00] = s00 * e00 + s01 * e01 + c * B0 * B0  # A_e (M C_g) A_eᵀ + C_e
        out[C01] = s00 * e10 + s01 * e11 + c * B0 * B1
        out[C11] = s10 * e10 + s11 * e11 + c * B1 * B1
        out[E0], out[E1] = h0 + eps * v0, h1 + eps * v1
        out[J00], out[J01], out[J11] = j00 + k * v0 * v0, j01 + k * v0 * v1, j11 + k * v1 * v1

    def prepend(self, at: slice, g: Elements, out: Elements) -> None:
        """The single frames ``at`` then ``g`` (n frames), into ``out``: :func:`combine` with C_i = c B Bᵀ of rank
        one, so (I + C_i J_g)⁻¹ = I − (c/ρ) B zᵀ with z = J_g B, ρ = 1 + c B·z (Sherman–Morrison)."""
        (F00, F01), (F10, F11) = self.F
        B0, B1 = self.B
        f0, f1 = self.f
        w, c, beta, y = self.w[at], self.c[at], self.beta[at], self.y[..., at]
        a00, a01, a10, a11, b0, b1, c00, c01, c11, h0, h1, j00, j01, j11 = g
        z0, z1 = j00 * B0 + j01 * B1, j01 * B0 + j11 * B1  # J_g B
        rho = 1.0 + c * (B0 * z0 + B1 * z1)
        k = c / rho
        r0, r1 = a00 * B0 + a01 * B1, a10 * B0 + a11 * B1  # A_g B
        gamma = (beta * y + c * (B0 * h0 + B1 * h1)) / rho  # M (b_e + C_e η_g) = γ B
        n0, n1 = h0 - beta * y * z0, h1 - beta * y * z1  # η_g − J_g b_e
        bn = B0 * n0 + B1 * n1
        n0, n1 = n0 - k * bn * z0, n1 - k * bn * z1  # Mᵀ (η_g − J_g b_e)
        t00, t01, t10, t11 = a00 - k * r0 * z0, a01 - k * r0 * z1, a10 - k * r1 * z0, a11 - k * r1 * z1  # A_g M
        i00, i01, i11 = j00 - k * z0 * z0, j01 - k * z0 * z1, j11 - k * z1 * z1  # Mᵀ J_g
        e00, e01, e10, e11 = F00 - beta * B0 * f0, F01 - beta * B0 * f1, F10 - beta * B1 * f0, F11 - beta * B1 * f1
        out[A00], out[A01] = t00 * e00 + t01 * e10, t00 * e01 + t01 * e11
        out[A10], out[A11] = t10 * e00 + t11 * e10, t10 * e01 + t11 * e11
        out[B0_], out[B1_] = gamma * r0 + b0, gamma * r1 + b1
        out[C00], out[C01], out[C11] = k * r0 * r0 + c00, k * r0 * r1 + c01, k * r1 * r1 + c11
        out[E0] = e00 * n0 + e10 * n1 + w * y * f0  # A_eᵀ Mᵀ (η_g − J_g b_e) + η_e
        out[E1] = e01 * n0 + e11 * n1 + w * y * f1
        s00, s01, s10, s11 = i00 * e00 + i01 * e10, i00 * e01 + i01 * e11, i01 * e00 + i11 * e10, i01 * e01 + i11 * e11
        out[J00] = e00 * s00 + e10 * s10 + w * f0 * f0  # A_eᵀ (Mᵀ J_g) A_e + J_e
        out[J01] = e00 * s01 + e10 * s11 + w * f0 * f1
        out[J11] = e01 * s01 + e11 * s11 + w * f1 * f1


def combine(ei: Elements, ej: Elements, covariance: bool = True) -> Elements:
    """``ei`` then ``ej`` (module docstring), elements of n frames each; ``covariance=False`` leaves the rows of C
    NaN (an estimate reads A, b, η and J only)."""
    a00, a01, a10, a11, b0, b1, c00, c01, c11, h0, h1, j00, j01, j11 = ei
    A00_, A01_, A10_, A11_, b0_, b1_, c00_, c01_, c11_, h0_, h1_, j00_, j01_, j11_ = ej
    cj00, cj01 = c00 * j00_ + c01 * j01_, c00 * j01_ + c01 * j11_  # C_i J_j
    cj10, cj11 = c01 * j00_ + c11 * j01_, c01 * j01_ + c11 * j11_
    det = (1.0 + cj00) * (1.0 + cj11) - cj01 * cj10
    m00, m01, m10, m11 = (1.0 + cj11) / det, -cj01 / det, -cj10 / det, (1.0 + cj00) / det  # M = (I + C_i J_j)⁻¹
    t00, t01 = A00_ * m00 + A01_ * m10, A00_ * m01 + A01_ * m11  # T = A_j M
    t10, t11 = A10_ * m00 + A11_ * m10, A10_ * m01 + A11_ * m11
    out = Elements.empty(a00.shape[-1], np.broadcast_shapes(b0.shape, b0_.shape)[:-1])
    out[A00], out[A01] = t00 * a00 + t01 * a10, t00 * a01 + t01 * a11
    out[A10], out[A11] = t10 * a00 + t11 * a10, t10 * a01 + t11 * a11
    u0, u1 = b0 + c00 * h0_ + c01 * h1_, b1 + c01 * h0_ + c11 * h1_  # b_i + C_i η_j
    out[B0_], out[B1_] = t00 * u0 + t01 * u1 + b0_, t10 * u0 + t11 * u1 + b1_
    if covariance:
        s00, s01 = t00 * c00 + t01 * c01, t00 * c01 + t01 * c11  # T C_i
        s10, s11 = t10 * c00 + t11 * c01, t10 * c01 + t11 * c11
        out[C00] = s00 * A00_ + s01 * A01_ + c00_  # T C_i A_jᵀ + C_j
        out[C01] = s00 * A10_ + s01 * A11_ + c01_
        out[C11] = s10 * A10_ + s11 * A11_ + c11_
    else:
        out[C00] = out[C01] = out[C11] = np.nan
    n00, n01 = m00 * a00 + m01 * a10, m00 * a01 + m01 * a11  # N = M A_i; A_iᵀ Mᵀ = Nᵀ
    n10, n11 = m10 * a00 + m11 * a10, m10 * a01 + m11 * a11
    v0, v1 = h0_ - (j00_ * b0 + j01_ * b1), h1_ - (j01_ * b0 + j11_ * b1)  # η_j − J_j b_i
    out[E0], out[E1] = n00 * v0 + n10 * v1 + h0, n01 * v0 + n11 * v1 + h1
    r00, r01 = j00_ * a00 + j01_ * a10, j00_ * a01 + j01_ * a11  # J_j A_i
    r10, r11 = j01_ * a00 + j11_ * a10, j01_ * a01 + j11_ * a11
    out[J00] = n00 * r00 + n10 * r10 + j00  # Nᵀ J_j A_i + J_i
    out[J01] = n00 * r01 + n10 * r11 + j01
    out[J11] = n01 * r01 + n11 * r11 + j11
    return out


class BlockLayout:
    """Frames of C channels cut into blocks of ``lengths`` (C,) frames (frames jL … jL + L − 1, the last block
    shorter), stored offset by offset: all blocks' frames at offset 0, then at offset 1, …, the blocks in
    order of decreasing length — so the blocks that reach offset i are the first ones at offset i − 1, and
    every scan step reads and writes contiguous slices (no gathers)."""

    def __init__(self, lengths: np.ndarray, T: int) -> None:
        n_blocks = -(-T // lengths)
        channel = np.repeat(np.arange(lengths.size), n_blocks)
        start = (np.arange(channel.size) - np.repeat(np.cumsum(n_blocks) - n_blocks, n_blocks)) * lengths[channel]
        size = np.minimum(lengths[channel], T - start)
        order = np.argsort(-size, kind="stable")
        channel, start, size = channel[order], start[order], size[order]
        self.count = np.searchsorted(-size, -np.arange(int(size.max(initial=0))), side="left")  # blocks at offset i
        self.base = np.concatenate([[0], np.cumsum(self.count)])  # first flat index of offset i
        offset = np.repeat(np.arange(self.count.size), self.count)
        rank = np.arange(self.base[-1]) - self.base[offset]
        self.channel, self.frame = channel[rank], start[rank] + offset  # (E,) of every flat index
        self.flat = np.empty((lengths.size, T), np.int64)  # flat index of (channel, frame)
        self.flat[self.channel, self.frame] = np.arange(self.channel.size)

    def scans(self, frames: FrameModel, work: tuple[np.ndarray, np.ndarray]) -> tuple[Elements, Elements]:
        """Prefix (block start … t) and suffix (t … block end) compositions of the E frames of ``frames`` (its arrays
        in this layout's flat order), written into ``work`` — structure (2, 10, >= E) and data (2, 4, …, >= E)
        arrays, reused across calls (their pages are touched once)."""
        E = self.base[-1]
        prefix, suffix = (Elements(work[0][j, :, :E], work[1][j, ..., :E]) for j in range(2))
        at = lambda i, n: slice(self.base[i], self.base[i] + n)  # noqa: E731  first n blocks at offset i
        frames.elements(at(0, self.count[0]), prefix.cols(at(0, self.count[0])))  # block starts
        for i in range(1, self.count.size):  # offsets within a block, not frames
            n = self.count[i]
            frames.append(prefix.cols(at(i - 1, n)), at(i, n), prefix.cols(at(i, n)))
        for i in range(self.count.size - 1, -1, -1):
            n = self.count[i + 1] if i + 1 < self.count.size else 0
            ends = slice(self.base[i] + n, self.base[i + 1])  # blocks whose last frame is at offset i
            if ends.stop > ends.start:
                frames.elements(ends, suffix.cols(ends))
            if n:
                frames.prepend(at(i, n), suffix.cols(at(i + 1, n)), suffix.cols(at(i, n)))
        return prefix, suffix


def window_estimates(layout: BlockLayout, prefix: Elements, suffix: Elements, lengths: np.ndarray,
                     channel: np.ndarray, lo: np.ndarray, hi: np.ndarray, mean: np.ndarray | None = None,
                     cov: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Estimates x_hi (…, P, 2) of the windows lo … hi of channel ``channel`` (each (P,), hi − lo < that channel's
    block length; … the leading data axes of the compositions) from one prefix and one suffix composition each —
    :func:`flat_prior_estimate`, or :func:`prior_estimate` with the prior ``mean`` (…, P, 2), ``cov`` (P, 2, 2) —
    and a mask (P,) of the windows that lie inside one block touching neither of its ends (estimate NaN: the
    caller computes those). Works in pieces of :data:`PIECE` windows of one kind (prefix only, suffix only, both),
    whose temporaries stay in cache (~4× faster than whole-array passes)."""
    L = lengths[channel]
    start = hi - hi % L  # the block of hi
    end = np.minimum(start + L - 1, layout.flat.shape[1] - 1)
    first, last = layout.flat[channel, lo], layout.flat[channel, hi]
    split = lo < start
    whole_prefix = lo == start
    whole_suffix = (hi == end) & ~split & ~whole_prefix
    inside = ~(split | whole_prefix | whole_suffix)
    compose = {  # the composition of windows w of each kind
        "prefix": lambda w: prefix.take(last[w]),
        "suffix": lambda w: suffix.take(first[w]),
        "split": lambda w: combine(suffix.take(first[w]), prefix.take(last[w]), covariance=False),
    }
    est = np.full((*prefix.parts[1].shape[1:-1], lo.size, 2), np.nan)
    for kind, windows in (("prefix", whole_prefix), ("suffix", whole_suffix), ("split", split)):
        windows = np.flatnonzero(windows)
        for k in range(0, windows.size, PIECE):
            w = windows[k:k + PIECE]
            g = compose[kind](w)
            est[..., w, :] = (flat_prior_estimate(g) if mean is None
                              else prior_estimate(g, mean[..., w, :], cast(np.ndarray, cov)[w]))  # given with mean
    return est, inside


def flat_prior_estimate(g: Elements) -> np.ndarray:
    """x_n (…, P, 2) from compositions ``g`` of P windows with a flat prior on the state before the window:
    A J⁻¹ η + b (J scaled to unit size first, so that its determinant cannot underflow)."""
    scale = np.maximum(np.abs(g[J00]), np.abs(g[J11]))
    j00, j01, j11, h0, h1 = (g[k] / scale for k in (J00, J01, J11, E0, E1))
    det = j00 * j11 - j01 * j01
    p0, p1 = (j11 * h0 - j01 * h1) / det, (j00 * h1 - j01 * h0) / det
    return np.stack([g[A00] * p0 + g[A01] * p1 + g[B0_], g[A10] * p0 + g[A11] * p1 + g[B1_]], axis=-1)


def prior_estimate(g: Elements, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """x_n (…, P, 2) from compositions ``g`` of P windows with the prior N(``mean`` (…, P, 2), ``cov`` (P, 2, 2)) on
    the state before the window: x̂ = μ + P0 (I + J P0)⁻¹ (η − J μ), then A x̂ + b."""
    m0, m1 = mean[..., 0], mean[..., 1]
    p00, p01, p11 = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    j00, j01, j11 = g[J00], g[J01], g[J11]
    v0, v1 = g[E0] - (j00 * m0 + j01 * m1), g[E1] - (j01 * m0 + j11 * m1)  # η − J μ
    i00, i01 = 1.0 + j00 * p00 + j01 * p01, j00 * p01 + j01 * p11  # I + J P0
    i10, i11 = j01 * p00 + j11 * p01, 1.0 + j01 * p01 + j11 * p11
    det = i00 * i11 - i01 * i10
    w0, w1 = (i11 * v0 - i01 * v1) / det, (i00 * v1 - i10 * v0) / det
    x0, x1 = m0 + p00 * w0 + p01 * w1, m1 + p01 * w0 + p11 * w1
    return np.stack([g[A00] * x0 + g[A01] * x1 + g[B0_], g[A10] * x0 + g[A11] * x1 + g[B1_]], axis=-1)
