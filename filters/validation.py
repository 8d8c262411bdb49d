"""Checks shared by every filter: each failure is a ``ValueError`` naming the parameter, the value and the
allowed range. Parameters may be scalars or arrays of shape (B,), one value per track."""

from __future__ import annotations

import numpy as np


def _describe(value: object) -> str:
    arr = np.asarray(value)
    if arr.ndim == 0:
        return repr(arr.item())
    bad = arr.ravel()[:3]
    return f"array of shape {arr.shape} (first values {bad.tolist()})"


def as_param(name: str, value: object) -> np.ndarray:
    """``value`` as a float array of shape () or (B,)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} must be a number or an array of shape (B,)") from None
    if arr.ndim > 1:
        raise ValueError(f"{name} has shape {arr.shape}; allowed: a scalar or shape (B,), one per track")
    return arr


def check_positive(name: str, value: object) -> np.ndarray:
    """Finite and > 0 (noise standard deviations, sampling time)."""
    arr = as_param(name, value)
    if not ((arr > 0) & (arr < np.inf)).all():  # NaN fails both comparisons
        raise ValueError(f"{name}={_describe(value)} is out of range: allowed finite values > 0")
    return arr


def check_psi(value: object) -> np.ndarray:
    """CMN coloredness factor, 0 <= ψ < 1."""
    arr = as_param("psi", value)
    if not ((arr >= 0) & (arr < 1)).all():  # NaN fails both comparisons
        raise ValueError(f"psi={_describe(value)} is out of range: allowed 0 <= psi < 1")
    return arr


def check_horizon(value: object, K: int, max_horizon: int = 100_000) -> np.ndarray:
    """FIR horizon N: an integer with K <= N <= max_horizon."""
    arr = as_param("horizon", value)
    if not ((arr >= K) & (arr <= max_horizon) & (arr == np.round(arr))).all():  # NaN fails every comparison
        raise ValueError(
            f"horizon={_describe(value)} is out of range: allowed integers {K} <= horizon <= {max_horizon}"
            f" (K={K} is the state size)"
        )
    return arr.astype(np.int64)


def check_measurements(y: object, M: int) -> tuple[np.ndarray, bool]:
    """``y`` shaped (T, M) or (B, T, M) → float array (B, T, M) and whether the input was batched.

    NaN marks a missing measurement; ±inf is rejected."""
    arr = np.asarray(y, dtype=float)
    if arr.ndim not in (2, 3):
        raise ValueError(f"y has rank {arr.ndim} (shape {arr.shape}); allowed: (T, M) or (B, T, M)")
    if arr.shape[-1] != M:
        raise ValueError(f"y has {arr.shape[-1]} measurement columns (shape {arr.shape}); the model has M={M}")
    if arr.shape[-2] < 1:
        raise ValueError(f"y has no frames (shape {arr.shape}); allowed: T >= 1")
    if np.isinf(arr).any():
        raise ValueError("y contains ±inf; allowed: finite values, or NaN for a missing measurement")
    batched = arr.ndim == 3
    return (arr if batched else arr[None]), batched


def broadcast_params(params: dict[str, np.ndarray], n_tracks: int, batched: bool) -> dict[str, np.ndarray]:
    """Broadcast scalar / (B,) parameters to shape (B,); (B,) arrays must match the batch of ``y``."""
    out = {}
    for name, arr in params.items():
        if arr.ndim == 1:
            if not batched:
                raise ValueError(
                    f"{name} has shape {arr.shape} but y is a single track (T, M); per-track parameter "
                    "arrays need y shaped (B, T, M)"
                )
            if arr.shape[0] != n_tracks:
                raise ValueError(f"{name} has shape {arr.shape}; y has B={n_tracks} tracks, allowed: () or ({n_tracks},)")
            out[name] = arr
        else:
            out[name] = np.full(n_tracks, arr, dtype=arr.dtype)
    return out
