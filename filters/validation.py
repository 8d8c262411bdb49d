"""Checks shared by every filter, and the documented valid ranges: each failure is a ``ValueError`` naming the
parameter, the value and the allowed range. Parameters may be scalars or arrays of shape (B,), one per track.

Valid ranges (every back end). Within them every intermediate of every back end stays inside float64 with
more than 100 orders of magnitude to spare (products of data / σ_v, covariances over σ_v² and priors reach
~1e150 at the corners), and the estimates keep their accuracy — measured against 40-digit mpmath references
(KF, KF-CMN, UKF, OFIR, OUFIR, FIR: <= 3e-13 relative for per-frame noise ratios σ_w τ²/σ_v from 1e-12 to
1e100; UFIR-CMN: see ψ):

=====================  ================================  =========================================================
quantity               allowed                           why
=====================  ================================  =========================================================
σ_w, σ_v, σ_c, σ_u     ``SIGMA_RANGE`` = [1e-30, 1e30]    noise scales; their ratios and squares, the diffuse
                                                         velocity prior (10³σ_v/τ)² and data / σ_v stay far from
                                                         over- and underflow
τ (model)              ``TAU_RANGE`` = [1e-6, 1e6] s      frame intervals from µs to days
ψ (kf_cmn, ufir_cmn)   0 <= ψ <= ``PSI_MAX`` = 0.99      UFIR-CMN's windows with missing samples lose accuracy
                                                         fast as ψ → 1 for short horizons (worst relative
                                                         position error, N = 3–6: 5e-10 at 0.95, 2e-8 at 0.98,
                                                         2e-7 at 0.99, 1e-3 at 0.999, all digits at 0.9999;
                                                         <= 2e-14 from N = 14 on); the envs' ψ range
horizon N (FIR)        integers 2 … 100,000              ``check_horizon``
α, β, κ (ukf)          [1e-4, 1e4], [0, 1e4], (−2, 1e4]  sigma-point scaling (bboxtune.filters.ukf: accurate over all of it)
y, u, x0 entries       finite, abs(·) <= ``VALUE_MAX`` = 1e30; NaN marks a missing y or u
P0 entries             abs(·) <= ``VARIANCE_MAX`` = 1e60   a variance of at most (1e30)²
P0 eigenvalues         <= ``PRIOR_MAX`` σ_v² = 1e8 σ_v²   per coordinate [p, v], in frame units [p, v τ]: a wider
                       (ofir: also >= 1e-30 σ_v²)         prior cancels in the first updates (relative error vs a
                                                         40-digit reference at 1e12 / 1e16: KF 3e-16 / 6e-4,
                                                         UKF 4e-7 / 7e-4, OFIR 3e-10 / 2e-4; at 1e8 all <= 2e-10).
                                                         The default diffuse velocity prior is 1e6 σ_v²
=====================  ================================  =========================================================

Within these ranges every back end returns finite estimates from a track's first finite measurement on (tested
with random parameters and data over the whole range; just outside, the ValueError names the parameter); a
non-finite estimate there raises ``FloatingPointError`` (:meth:`bboxtune.filters.base.Filter.run`) instead of being
returned.
"""

from __future__ import annotations

import numpy as np

from bboxtune.filters.blocks import split_covariance

SIGMA_RANGE = (1e-30, 1e30)  # any noise standard deviation (units, units/s², units/s)
TAU_RANGE = (1e-6, 1e6)  # s, sampling interval
PSI_MAX = 0.99  # CMN coloredness
VALUE_MAX = 1e30  # |y|, |u|, |x0|
VARIANCE_MAX = 1e60  # |P0| entries
PRIOR_MAX = 1e8  # a prior covariance's eigenvalues in frame units ([p, v τ]) at most PRIOR_MAX σ_v²
SMALL_PARAM = 16  # parameter arrays of at most this many entries are range-checked by Python comparisons


def _describe(value: object, ok: np.ndarray | None = None) -> str:
    """``value`` for an error message; for an array, its shape and the first entry failing ``ok``."""
    arr = np.asarray(value)
    if arr.ndim == 0:
        return repr(arr.item())
    if ok is not None and not np.all(ok):
        i = int(np.argmin(np.asarray(ok).ravel()))
        return f"array of shape {arr.shape} with entry [{i}] = {arr.ravel()[i].item()!r}"
    return f"array of shape {arr.shape} (first values {arr.ravel()[:3].tolist()})"


def short_repr(value: object, limit: int = 60) -> str:
    """``repr(value)`` on one line (runs of whitespace as one space), cut to ``limit`` characters with "..."."""
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def numeric(name: str, value: object, allowed: str) -> np.ndarray:
    """``value`` as a float array of any shape. Only numbers are taken (int, float, NumPy integer or floating
    scalars and arrays): a str such as ``'1'``, a bool, None or any other object is never coerced but refused with
    a TypeError naming ``name`` and what is ``allowed``."""
    try:
        arr = None if isinstance(value, (str, bytes)) else np.asarray(value)
    except (TypeError, ValueError):  # ragged nested sequences
        arr = None
    if arr is None or arr.dtype.kind not in "iuf":
        raise TypeError(f"{name}={short_repr(value)} ({type(value).__name__}) is not a number; allowed: {allowed}")
    return arr.astype(float)


def as_param(name: str, value: object, allowed: str = "") -> np.ndarray:
    """``value`` as a float array of shape () or (B,) (:func:`numeric`: TypeError for a value that is not a number;
    ``allowed`` the range, e.g. ``"1e-30 <= sigma_w <= 1e+30"``, for its message)."""
    arr = numeric(name, value, "a number or an array of shape (B,) of numbers (int or float)"
                  + (f" with {allowed}" if allowed else ""))
    if arr.ndim > 1:
        raise ValueError(f"{name} has shape {arr.shape}; allowed: a scalar or shape (B,), one per track")
    return arr


def _param_array(value: object) -> np.ndarray | None:
    """``value`` as a new float array when it already is a float scalar or a float array of shape () or (B,) (the
    common case, without building :func:`as_param`'s message strings); None for anything else (then
    :func:`as_param` converts or refuses it)."""
    if type(value) is float:
        return np.array(value)
    if type(value) is np.ndarray and value.dtype == np.float64 and value.ndim <= 1:
        return value.copy()
    return None


def _all_within(arr: np.ndarray, low: float, high: float, low_open: bool = False) -> bool:
    """Whether every entry of ``arr`` lies in the range (NaN never does): Python comparisons for the few entries of a
    parameter (a few µs less than numpy's), numpy's for more."""
    if arr.size <= SMALL_PARAM:
        return all((low < v if low_open else low <= v) and v <= high for v in arr.reshape(-1).tolist())
    return bool((((arr > low) if low_open else (arr >= low)) & (arr <= high)).all())


def check_range(name: str, value: object, low: float, high: float, low_open: bool = False) -> np.ndarray:
    """A float array of shape () or (B,) with ``low <= value <= high`` (``low < value`` if ``low_open``);
    :func:`as_param`'s TypeError for a value that is not a number."""
    arr = _param_array(value)
    if arr is not None and _all_within(arr, low, high, low_open):
        return arr
    allowed = f"{low:g} {'<' if low_open else '<='} {name} <= {high:g}"
    arr = as_param(name, value, allowed)
    ok = ((arr > low) if low_open else (arr >= low)) & (arr <= high)  # NaN fails both comparisons
    if not ok.all():
        raise ValueError(f"{name}={_describe(value, ok)} is out of range: allowed {allowed}")
    return arr


def check_sigma(name: str, value: object) -> np.ndarray:
    """A noise standard deviation within :data:`SIGMA_RANGE`."""
    return check_range(name, value, *SIGMA_RANGE)


def check_tau(value: object) -> np.ndarray:
    """The sampling interval τ (s) within :data:`TAU_RANGE`."""
    return check_range("tau", value, *TAU_RANGE)


def check_psi(value: object) -> np.ndarray:
    """CMN coloredness factor, 0 <= ψ <= :data:`PSI_MAX`."""
    return check_range("psi", value, 0.0, PSI_MAX)


def check_prior_scale(blocks: np.ndarray, sigma_v: np.ndarray, tau: float, low: float = 0.0) -> None:
    """Prior covariance blocks (m, 2, 2) of [position, velocity]: in frame units (``diag(1, τ) P diag(1, τ)``) their
    eigenvalues must lie within [``low``, :data:`PRIOR_MAX`] times σ_v² for every track's σ_v."""
    S = np.diag([1.0, tau])
    eig = np.linalg.eigvalsh(S @ blocks @ S)
    sigma_v = np.asarray(sigma_v)
    high, small = eig.max() / np.min(sigma_v) ** 2, eig.min() / np.max(sigma_v) ** 2
    if not (high <= PRIOR_MAX * (1 + 1e-9) and small >= low * (1 - 1e-9)):  # bounds hit exactly pass despite rounding
        raise ValueError(f"P0 has frame-unit eigenvalues from {eig.min():.3g} to {eig.max():.3g} (sigma_v from "
                         f"{np.min(sigma_v):g} to {np.max(sigma_v):g}, tau={tau!r}): out of range: allowed eigenvalues "
                         f"within [{low:g}, {PRIOR_MAX:g}] × sigma_v² per coordinate, in frame units [p, v·tau]")


def check_horizon(value: object, K: int, max_horizon: int = 100_000) -> np.ndarray:
    """FIR horizon N: an integer with K <= N <= max_horizon."""
    if type(value) is np.ndarray and value.dtype == np.int64 and value.ndim <= 1 and _all_within(value, K, max_horizon):
        return value.copy()  # integers in range (the common case, checked without building the messages)
    arr = as_param("horizon", value, f"{K} <= horizon <= {max_horizon}, an integer")
    ok = (arr >= K) & (arr <= max_horizon) & (arr == np.round(arr))  # NaN fails every comparison
    if not ok.all():
        raise ValueError(
            f"horizon={_describe(value, ok)} is out of range: allowed integers {K} <= horizon <= {max_horizon}"
            f" (K={K} is the state size)"
        )
    return arr.astype(np.int64)


def check_values(name: str, arr: np.ndarray, nan_ok: bool = True) -> None:
    """Entries finite (NaN allowed if ``nan_ok``: a missing value) with abs(·) <= :data:`VALUE_MAX`; no temporary
    copies of ``arr`` (NaN-ignoring reductions), so checking a large batch costs no memory."""
    if arr.size == 0:
        return
    high, low = np.fmax.reduce(arr, axis=None), np.fmin.reduce(arr, axis=None)  # NaN only if all entries are
    missing = "NaN for a missing value" if nan_ok else "no NaN"
    if not nan_ok and np.isnan(arr).any():
        raise ValueError(f"{name} contains NaN; allowed: finite values with |{name}| <= {VALUE_MAX:g}, {missing}")
    if (np.isfinite(high) and np.isfinite(low)) or (np.isnan(high) and np.isnan(low)):
        extreme = max(abs(high), abs(low)) if np.isfinite(high) else 0.0
        if extreme <= VALUE_MAX:
            return
        raise ValueError(f"{name} contains {extreme:.3g}; allowed: finite values with |{name}| <= {VALUE_MAX:g}, "
                         f"or {missing}")
    raise ValueError(f"{name} contains ±inf; allowed: finite values with |{name}| <= {VALUE_MAX:g}, or {missing}")


def check_measurements(y: object, M: int) -> tuple[np.ndarray, bool]:
    """``y`` shaped (T, M) or (B, T, M) → float array (B, T, M) and whether the input was batched.

    NaN marks a missing measurement; ±inf and abs(y) > :data:`VALUE_MAX` are rejected. B = 0 tracks and T = 0
    frames are allowed (the filters then return empty arrays)."""
    try:
        arr = np.asarray(y, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"y is not an array of numbers ({err}); allowed: (T, M) or (B, T, M) floats") from None
    if arr.ndim not in (2, 3):
        raise ValueError(f"y has rank {arr.ndim} (shape {arr.shape}); allowed: (T, M) or (B, T, M)")
    if arr.shape[-1] != M:
        raise ValueError(f"y has {arr.shape[-1]} measurement columns (shape {arr.shape}); the model has M={M}")
    check_values("y", arr)
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


def check_prior(x0: object, P0: object, K: int, M: int, sigma_v: np.ndarray,
                tau: float) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Validate the full-model prior: ``x0`` None or finite (K,) with entries within ±``VALUE_MAX``; ``P0`` None or
    symmetric positive semi-definite (K, K) with entries within ±``VARIANCE_MAX`` that does not couple different
    coordinates and whose per-coordinate blocks, in frame units, have eigenvalues <= ``PRIOR_MAX`` × every track's
    ``sigma_v``² (the module docstring's ranges; the model's interval ``tau``): the Kalman back ends' prior."""
    x = None
    if x0 is not None:
        x = numeric("x0", x0, f"None or a finite array of shape ({K},) with |x0| <= {VALUE_MAX:g}")
        if x.shape != (K,) or not np.all(np.abs(x) <= VALUE_MAX):
            raise ValueError(f"x0={x0!r} (shape {x.shape}) is invalid: allowed None or a finite array of shape ({K},) "
                             f"with |x0| <= {VALUE_MAX:g}")
    P = None
    if P0 is not None:
        P = numeric("P0", P0, f"None or a finite array of shape ({K}, {K}) with |P0| <= {VARIANCE_MAX:g}")
        if P.shape != (K, K) or not np.all(np.abs(P) <= VARIANCE_MAX):
            raise ValueError(f"P0 has shape {P.shape} (max |P0| = {np.max(np.abs(P), initial=0):.3g}): allowed None or "
                             f"a finite array of shape ({K}, {K}) with |P0| <= {VARIANCE_MAX:g}")
        scale = np.max(np.abs(P))
        if np.max(np.abs(P - P.T)) > 1e-12 * scale:
            raise ValueError(f"P0 is not symmetric (max |P0 − P0ᵀ| = {np.max(np.abs(P - P.T)):.3g}); allowed: "
                             "a symmetric positive semi-definite matrix")
        low = np.linalg.eigvalsh(P).min()
        if low < -1e-12 * scale:
            raise ValueError(f"P0 has eigenvalue {low:.3g} < 0; allowed: a symmetric positive semi-definite matrix")
        check_prior_scale(split_covariance(P, M), sigma_v, tau)
    return x, P
