"""The simulator's detection noise fitted to MOT15's train split, and the same statistics measured on the simulator.

:func:`noise_stats` measures a set of identity episodes (:class:`bboxtune.envs.data.mot.MOTIdentity`): everything
:func:`bboxtune.envs.data.mot.detection_stats` reports, pooled over the set and for each identity alone (the statistics
code is that function's, called once per identity). :func:`fit_sim_kwargs` turns the train split's numbers into
``bboxtune/FilterTune-v0`` keyword arguments; :func:`measure_sim` draws episodes of such an env and measures them
with :func:`noise_stats`, so the comparison with MOT is like for like. The choices of the fit:

* **Noise model**: ``source="sim"``, ``sim_noise="box"``: box-relative Gauss–Markov CMN u_n = ψ u_{n−1} + ξ_n,
  ξ ~ N(0, σ_rel²), one channel per coordinate, cx += w·u, cy += h·u, w·exp(u), h·exp(u); per episode ψ uniform
  in ``psi_range`` and σ_rel log-uniform in ``cmn_rel_range``, shared by the four channels. MOT's statistics divide
  every error by the true height h, so in the model's units (w for cx and w, h for cy and h) an error std
  s_k / h is s_k / (aspect · h) for cx and w: ``aspect`` is the median true w / h of the split's boxes
  (:func:`box_aspect`; MOT15 train pedestrians: 0.385).
* **ψ** (``psi_range``): the 10th–90th percentiles (:data:`QUANTILES`) of the per-identity lag-1 correlations of
  the four coordinates together, over identities with at least :data:`MIN_LAG_PAIRS` pairs of consecutive
  detections (fewer pairs give a correlation too noisy to count), clipped to [0, 0.95] (:data:`PSI_BOUNDS`).
* **σ_rel** (``cmn_rel_range``): one σ_rel drives the four channels, while a real detector's errors in model
  units differ per coordinate (MOT15 train: x 0.11 of w, y 0.045 of h, w 0.18 of w, h 0.10 of h), so the fit
  matches their mean square, the total error power: the pooled stationary variance of the drawn noise,
  E[σ_rel²] · E[1 / (1 − ψ²)] (:func:`stationary_std`; ψ and σ_rel are drawn independently), equals the mean over
  the coordinates of (pooled error std in model units)². The range's width hi / lo is the 90th / 10th
  percentile ratio of the per-identity error level (the root mean square over the coordinates of each
  identity's error std in model units, same identities as for ψ). The residual per-coordinate mismatch shows in
  the comparison table.
* **Range ends**: a range's ends are the percentiles themselves, not widened: each identity's value is a noisy
  estimate, whose spread across identities exceeds that of the underlying parameter by roughly as much as a
  uniform draw's 10th–90th percentiles sit inside its range; the simulator's per-identity values, measured the
  same way, are the check (``fit.md`` of ``scripts/mot_fit.py``).
* **Misses** (``detection_dropout="runs"``: Gilbert–Elliott runs, :mod:`bboxtune.envs.data.sim_detections`):
  ``miss_rate_range`` is the 10th–90th percentiles of the per-identity miss rates, clipped to [0, 0.95];
  ``miss_run_range`` (the mean run length L, log-uniform) the 10th–90th percentiles of the per-identity mean
  missed-run lengths (identities with at least one run), clipped to [1, 1000]. Wrong boxes
  (``outlier_rate_range``) stay off: a detection is matched to an identity only at IoU >= 0.5, so MOT's
  matched errors hold no wrong-object box to fit.
* **Episodes**: ``tau_range`` = (1/30, 1/7) s (MOT15 runs at 7–30 frames/s); ``track_length`` the median
  identity length of the split; ``box_size_range`` (initial w and h, px) the 10th–90th percentiles of the
  per-identity median true height, within ``EnvConfig.box_size_bounds`` (4–1000 px); ``motion="otb"``:
  scale-relative motion fitted to OTB-100 ground truth (:mod:`bboxtune.envs.data.sim_motion`), as pedestrians move in
  proportion to their box size (the "cv" default's absolute σ_w of 1–100 px/s² is not scale-relative, and
  ``docs/otb_motion.md`` measured it about a decade too slow on real ground truth).

Every fitted number is rounded to 4 significant digits (:data:`DIGITS`) so the kwargs read well on a command line.

**Box shape**: the simulator draws w and h independently from ``box_size_range`` (``EnvConfig`` has no aspect
ratio), so its boxes are not pedestrian-shaped. Its noise is box-relative, so :func:`measure_sim` measures each
episode with w reshaped to ``aspect`` · h per frame (true and measured w scaled by aspect · h / w, the cx error
by the same factor): exactly the errors the drawn u give on boxes of MOT's shape, the cy and h errors unchanged.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.data.mot import DetectionStats, MOTIdentity, detection_stats
from bboxtune.envs.data.sim_detections import finite_rows
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.sources import make_source

MIN_LAG_PAIRS = 20  # pairs of consecutive detections an identity needs for its own lag-1 correlation / error level
QUANTILES = (0.1, 0.9)  # the percentiles a range spans
PSI_BOUNDS = (0.0, 0.95)
MISS_RATE_BOUNDS = (0.0, 0.95)
MISS_RUN_BOUNDS = (1.0, 1000.0)  # frames (EnvConfig's miss_run_range limits)
SIZE_BOUNDS = (4.0, 1000.0)  # px, EnvConfig's default box_size_bounds
TAU_RANGE = (1 / 30, 1 / 7)  # s: MOT15 sequences run at 7–30 frames/s
DIGITS = 4  # significant digits of the fitted numbers


@dataclass(frozen=True, eq=False)
class NoiseStats:
    """Detection statistics of a set of identity episodes: pooled and per identity (module docstring)."""

    pooled: DetectionStats  # detection_stats of the whole set
    lag1_corr: np.ndarray  # (n, 4) each identity's own lag-1 correlation of error / h; NaN below MIN_LAG_PAIRS pairs
    lag_pairs: np.ndarray  # (n,) its pairs of consecutive detections
    error_mean_rel: np.ndarray  # (n, 4) each identity's mean error / h
    error_std_rel: np.ndarray  # (n, 4) each identity's error std / h
    matched: np.ndarray  # (n,) each identity's matched detections
    mean_miss_run: np.ndarray  # (n,) each identity's mean missed-run length (frames), NaN without runs
    median_height: np.ndarray  # (n,) each identity's median true height (px)
    error_rel_cx: np.ndarray  # (n_matched,) the x-centre error / h of every matched frame

    @property
    def well_measured(self) -> np.ndarray:
        """(n,) whether an identity has the MIN_LAG_PAIRS pairs its own correlation and error level need."""
        return self.lag_pairs >= MIN_LAG_PAIRS

    def between_share(self) -> np.ndarray:
        """(4,) the share of the pooled error variance (of error / h) that lies between the identities' mean
        errors: persistent per-identity offsets (0 for stationary zero-mean noise on long episodes)."""
        offsets = self.error_mean_rel - self.pooled.error_mean_rel
        return (self.matched[:, None] * offsets**2).sum(axis=0) / self.matched.sum() / self.pooled.error_std_rel**2


def _alone(identity: MOTIdentity) -> DetectionStats:
    """detection_stats of one identity; one without consecutive detections gets NaN correlations, quietly."""
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)  # numpy's "mean of empty slice"
        return detection_stats([identity])


def noise_stats(identities: Sequence[MOTIdentity]) -> NoiseStats:
    """The pooled and per-identity statistics of ``identities`` (at least one)."""
    pooled = detection_stats(identities)
    alone = [_alone(identity) for identity in identities]
    pairs = np.array([s.n_lag_pairs for s in alone])
    lag1 = np.array([s.lag1_corr for s in alone])
    lag1[pairs < MIN_LAG_PAIRS] = np.nan
    errors = []
    for identity in identities:
        truth, measured = xywh_to_cxcywh(identity.truth), xywh_to_cxcywh(identity.measured)
        error = (measured[:, 0] - truth[:, 0]) / truth[:, 3]
        errors.append(error[np.isfinite(error)])
    return NoiseStats(
        pooled=pooled, lag1_corr=lag1, lag_pairs=pairs, error_mean_rel=np.array([s.error_mean_rel for s in alone]),
        error_std_rel=np.array([s.error_std_rel for s in alone]), matched=np.array([s.n_matched for s in alone]),
        mean_miss_run=np.array([s.miss_runs.mean() if len(s.miss_runs) else np.nan for s in alone]),
        median_height=np.array([np.nanmedian(i.truth[:, 3]) for i in identities]),
        error_rel_cx=np.concatenate(errors))


def box_aspect(identities: Sequence[MOTIdentity]) -> float:
    """The median true w / h over every frame with ground truth of ``identities``."""
    ratios = np.concatenate([i.truth[:, 2] / i.truth[:, 3] for i in identities])
    return float(np.nanmedian(ratios))


def _units(aspect: float) -> np.ndarray:
    """(4,) what the model scales each coordinate's noise by (w, h, w, h), in true heights h."""
    return np.array([aspect, 1.0, aspect, 1.0])


def _round(x: float) -> float:
    return float(f"{x:.{DIGITS}g}")


def _span(values: np.ndarray, bounds: tuple[float, float], what: str) -> list[float]:
    """The QUANTILES of the finite ``values``, clipped to ``bounds`` and rounded; ValueError when there are none."""
    finite = values[np.isfinite(values)]
    if not finite.size:
        raise ValueError(f"no {what} to fit a range to")
    return [_round(v) for v in np.clip(np.quantile(finite, QUANTILES), *bounds)]


def stationary_std(psi_range: Sequence[float], cmn_rel_range: Sequence[float]) -> float:
    """sqrt(E[σ_rel²] · E[1 / (1 − ψ²)]): the pooled stationary std of the CMN u when ψ is uniform in
    ``psi_range`` and σ_rel log-uniform in ``cmn_rel_range``, drawn independently."""
    (p0, p1), (a, b) = psi_range, cmn_rel_range
    gain = 1 / (1 - p0**2) if p1 == p0 else (np.arctanh(p1) - np.arctanh(p0)) / (p1 - p0)
    power = a**2 if b == a else (b**2 - a**2) / (2 * np.log(b / a))
    return float(np.sqrt(power * gain))


def fit_sim_kwargs(stats: NoiseStats, aspect: float) -> dict[str, Any]:
    """``bboxtune/FilterTune-v0`` kwargs of the simulator with detection noise fitted to ``stats`` (module
    docstring), for boxes of median w / h ``aspect``; ranges are lists, checked by ``EnvConfig``."""
    if not (np.isfinite(aspect) and aspect > 0):
        raise ValueError(f"aspect={aspect!r}; allowed: a finite box w / h > 0")
    units = _units(aspect)
    psi_range = _span(stats.lag1_corr[stats.well_measured].ravel(), PSI_BOUNDS,
                      f"identity with {MIN_LAG_PAIRS} pairs of consecutive detections")
    target = float(np.sqrt(np.mean((stats.pooled.error_std_rel / units) ** 2)))
    levels = np.sqrt(np.mean((stats.error_std_rel[stats.well_measured] / units) ** 2, axis=1))
    low, high = np.quantile(levels, QUANTILES)
    ratio = float(high / low) if low > 0 else 1.0
    lowest = target / stationary_std(psi_range, (1.0, ratio))  # the range (1, ratio) scaled to the target
    kwargs: dict[str, Any] = {
        "source": "sim", "sim_noise": "box", "motion": "otb", "psi_range": psi_range,
        "cmn_rel_range": [_round(v) for v in np.clip([lowest, lowest * ratio], 1e-4, 1.0)],
        "detection_dropout": "runs",
        "miss_rate_range": _span(stats.pooled.miss_rate, MISS_RATE_BOUNDS, "miss rate"),
        "miss_run_range": _span(stats.mean_miss_run, MISS_RUN_BOUNDS, "missed run"),
        "tau_range": [_round(t) for t in TAU_RANGE],
        "track_length": int(round(float(np.median(stats.pooled.track_length)))),
        "box_size_range": _span(stats.median_height, SIZE_BOUNDS, "box height"),
    }
    EnvConfig(**kwargs)  # every value within the env's limits
    return kwargs


def _pedestrian_shaped(truth: np.ndarray, y: np.ndarray, aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """(cx, cy, w, h) truth and measurements (T, 4) with the true w set to ``aspect`` · h and the measured w and
    cx error scaled by the same factor (module docstring, "Box shape")."""
    factor = aspect * truth[:, 3] / truth[:, 2]
    shaped_truth, shaped_y = truth.copy(), y.copy()
    shaped_truth[:, 2] = aspect * truth[:, 3]
    shaped_y[:, 0] = truth[:, 0] + factor * (y[:, 0] - truth[:, 0])
    shaped_y[:, 2] = factor * y[:, 2]
    return shaped_truth, shaped_y


def sim_identities(kwargs: dict[str, Any], n_episodes: int, seed: int, *, aspect: float) -> list[MOTIdentity]:
    """The episodes of noise seeds ``seed`` … ``seed + n_episodes − 1`` of the "sim" env ``kwargs`` (what
    ``gym.make("bboxtune/FilterTune-v0", **kwargs)`` plays for those noise seeds) as identity episodes,
    pedestrian-shaped (module docstring); ``identity`` is the noise seed."""
    cfg = EnvConfig(**kwargs)
    if cfg.source != "sim":
        raise ValueError(f"source={cfg.source!r}; measure_sim measures the 'sim' source only")
    if n_episodes < 1:
        raise ValueError(f"n_episodes={n_episodes}; allowed: >= 1")
    out = []
    for noise_seed, episode in zip(range(seed, seed + n_episodes), make_source(cfg).draw_many(
            list(range(seed, seed + n_episodes))), strict=False):
        truth, y = _pedestrian_shaped(episode.truth, episode.y, aspect)
        out.append(MOTIdentity(sequence="sim", identity=noise_seed, first_frame=1, truth=cxcywh_to_xywh(truth),
                               measured=cxcywh_to_xywh(y), scores=np.where(finite_rows(y), 1.0, np.nan),
                               tau=episode.tau))
    return out


def measure_sim(kwargs: dict[str, Any], n_episodes: int, seed: int, *, aspect: float) -> NoiseStats:
    """:func:`noise_stats` of ``n_episodes`` episodes of the "sim" env ``kwargs`` (:func:`sim_identities`)."""
    return noise_stats(sim_identities(kwargs, n_episodes, seed, aspect=aspect))
