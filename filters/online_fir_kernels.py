"""Compiled kernels of the FIR family's online engine (:meth:`bboxtune.filters.online_fir.WindowGroups.newest_positions`,
their numpy reference): each frame's window kinds and its newest estimates.

* :func:`window_kinds` codes every channel's window (gain group, window length, which samples it has) as one int64,
  as the reference does, and groups equal codes as ``np.unique`` does (kinds numbered in ascending code order; each
  kind's first channel);
* :func:`newest_estimates` applies each channel's gain to its window (missing samples count 0) and, where the window
  does not determine the state (a NaN gain), holds the channel's latest measurement.

The kinds and the fallback are exact; the weighted sums add the samples in window order where the reference's
einsum may pair them, so the estimates agree to rounding (property tests: tests/filters/test_online_fir_kernels.py).
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters import jit


def window_kinds(window: np.ndarray, lengths: np.ndarray, group: np.ndarray,
                 n_groups: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The window kinds of channels ``window`` (C, L) (right-aligned: channel c's window is its last ``lengths[c]``
    samples, NaN = missing) of gain groups ``group`` (C,) among ``n_groups``: each kind's code ((mask bits + length ·
    2^L) · n_groups + group) in ascending order (U,), its first channel (U,) and each channel's kind (C,), as
    ``np.unique(codes, return_index=True, return_inverse=True)``. Needs 2L + bit_length(n_groups) <= 62 (the codes
    fit in 63 bits)."""
    return _window_kinds(np.ascontiguousarray(window, dtype=np.float64), np.ascontiguousarray(lengths, dtype=np.int64),
                         np.ascontiguousarray(group, dtype=np.int64), n_groups)


def newest_estimates(W: np.ndarray, kind: np.ndarray, window: np.ndarray, lengths: np.ndarray,
                     z: np.ndarray) -> tuple[np.ndarray, int]:
    """The estimates (C,) Σ_l W[kind[c], l] · window[c, l] over each channel's window samples (the others count 0),
    ``W`` (U, L) the gains of the kinds (NaN rows: the window does not determine the state); where that is NaN, the
    latest measurement of the channel's span ``z`` (C, S) (NaN before any). Also the first channel whose gain is
    finite but whose estimate is not (−1 if none: the caller reports it)."""
    return _newest_estimates(np.ascontiguousarray(W, dtype=np.float64), np.ascontiguousarray(kind, dtype=np.int64),
                             np.ascontiguousarray(window, dtype=np.float64),
                             np.ascontiguousarray(lengths, dtype=np.int64), np.ascontiguousarray(z, dtype=np.float64))


@jit.kernel
def _window_kinds(window: np.ndarray, lengths: np.ndarray, group: np.ndarray, n_groups: int) -> tuple:
    C, L = window.shape
    codes = np.empty(C, np.int64)
    for c in range(C):
        bits = np.int64(0)
        for j in range(L - lengths[c], L):
            if not np.isnan(window[c, j]):
                bits |= np.int64(1) << np.int64(j)
        codes[c] = (bits + (lengths[c] << np.int64(L))) * n_groups + group[c]
    order = np.argsort(codes, kind="mergesort")  # stable: each run of equal codes starts with its first channel
    kind = np.empty(C, np.int64)
    first = np.empty(C, np.int64)
    n_kinds = 0
    for i in range(C):
        c = order[i]
        if i == 0 or codes[c] != codes[order[i - 1]]:
            first[n_kinds] = c
            n_kinds += 1
        kind[c] = n_kinds - 1
    first = first[:n_kinds].copy()
    return codes[first], first, kind


@jit.kernel
def _newest_estimates(W: np.ndarray, kind: np.ndarray, window: np.ndarray, lengths: np.ndarray,
                      z: np.ndarray) -> tuple:
    C, L = window.shape
    S = z.shape[1]
    out = np.empty(C)
    failed = -1
    for c in range(C):
        w = W[kind[c]]
        acc = 0.0
        for j in range(L):
            x = window[c, j]
            acc += w[j] * (x if j >= L - lengths[c] and not np.isnan(x) else 0.0)
        if np.isnan(acc):
            if failed < 0 and not np.isnan(w[L - 1]):
                failed = c
            acc = np.nan  # undetermined: the latest measurement of the span, NaN before any
            for n in range(S - 1, -1, -1):
                if not np.isnan(z[c, n]):
                    acc = z[c, n]
                    break
        out[c] = acc
    return out, failed
