"""The check every run ends with (:meth:`bboxtune.filters.base.Filter.run`, ``positions``, ``run_from``): the first
non-finite estimate at or after a channel's first finite measurement, as compiled kernels (:mod:`bboxtune.filters.jit`)
beside their numpy references; for ``positions`` one pass that also writes the channels' positions out per track."""

from __future__ import annotations

import math

import numpy as np

from bboxtune.filters import jit


def first_nonfinite_numpy(axes: np.ndarray, z: np.ndarray) -> tuple[int, int] | None:
    """(channel, frame) of the first (channel-major) non-finite estimate of ``axes`` (C, T, k) at or after the
    channel's first finite measurement in ``z`` (C, T), or None: the numpy reference."""
    bad = np.maximum.accumulate(~np.isnan(z), axis=1)[..., None] & ~np.isfinite(axes)
    if not bad.any():
        return None
    c, t, _ = np.argwhere(bad)[0]
    return int(c), int(t)


@jit.kernel
def _first_nonfinite_kernel(finite: np.ndarray, z: np.ndarray) -> int:
    """Flat index c·T + t of the first estimate that is not ``finite`` (C, T) at or after channel c's first
    non-NaN ``z`` (C, T); -1 if there is none."""
    n_channels, T = z.shape
    for c in range(n_channels):
        started = False
        for t in range(T):
            started = started or not math.isnan(z[c, t])
            if started and not finite[c, t]:
                return c * T + t
    return -1


def first_nonfinite(axes: np.ndarray, z: np.ndarray) -> tuple[int, int] | None:
    """:func:`first_nonfinite_numpy`, by the compiled kernel unless ``$BBOXTUNE_JIT=0``."""
    if not jit.enabled():
        return first_nonfinite_numpy(axes, z)
    finite = np.isfinite(axes[..., 0]) if axes.shape[-1] == 1 else np.isfinite(axes).all(axis=-1)
    at = _first_nonfinite_kernel(np.ascontiguousarray(finite), np.ascontiguousarray(z, dtype=np.float64))
    return None if at < 0 else divmod(at, z.shape[1])


def write_positions_numpy(axes: np.ndarray, z: np.ndarray, out: np.ndarray) -> tuple[int, int] | None:
    """Write the positions ``axes[..., 0]`` of channels (C, T) (channel c = track c // M, coordinate c % M) into
    ``out`` (C / M, T, M), and return :func:`first_nonfinite_numpy` of them: the numpy reference."""
    n_tracks, T, M = out.shape
    out[:] = axes[..., 0].reshape(n_tracks, M, T).transpose(0, 2, 1)
    return first_nonfinite_numpy(axes[..., :1], z)


@jit.kernel
def _write_positions_kernel(positions: np.ndarray, z: np.ndarray, out: np.ndarray) -> int:
    """``positions`` (C, T) into ``out`` (C / M, T, M); the flat index c·T + t of the first non-finite one at or after
    channel c's first non-NaN ``z`` (C, T), or -1."""
    n_channels, T = z.shape
    M = out.shape[2]
    first_bad = -1
    for c in range(n_channels):
        track, coordinate = c // M, c % M
        started = False
        for t in range(T):
            value = positions[c, t]
            out[track, t, coordinate] = value
            started = started or not math.isnan(z[c, t])
            if first_bad < 0 and started and not math.isfinite(value):
                first_bad = c * T + t
    return first_bad


def write_positions(axes: np.ndarray, z: np.ndarray, out: np.ndarray) -> tuple[int, int] | None:
    """:func:`write_positions_numpy`, by the compiled kernel unless ``$BBOXTUNE_JIT=0``; ``out`` C-contiguous float64."""
    if not jit.enabled():
        return write_positions_numpy(axes, z, out)
    at = _write_positions_kernel(axes[..., 0], np.ascontiguousarray(z, dtype=np.float64), out)
    return None if at < 0 else divmod(at, z.shape[1])
