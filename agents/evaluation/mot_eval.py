"""Filters on real detection streams: the MOT15 identity protocol (``../shared/notes/mot-baselines.md``).

Each episode is one ground-truth identity measured by the public detections matched to it
(:mod:`bboxtune.envs.episodes.mot_source`: from its first to its last matched detection, boxes cx, cy, w, h in px). Every
method runs causally on the detection stream and returns an estimate per frame (NaN where it has none). Per
identity (:func:`identity_scores`):

* ``iou_detected``: mean IoU with the ground truth over the *detected* frames — frames with a matched detection —
  from the :data:`WARMUP`-th frame after the first detection on (a filter's start-up is not scored);
* ``iou_gap_sum`` / ``n_gap``: IoU summed over, and the number of, *gap* frames — frames between the first and
  the last detection without one, with ground truth; an estimate that is missing there scores IoU 0 (the raw
  detections fill nothing). Gap IoU is pooled over frames: Σ iou_gap_sum / Σ n_gap;
* ``sq_detected``: the mean squared (cx, cy, w, h) error (px²) over the detected frames, so that
  log(RMSE_raw / RMSE) compares every method on the same frames.

Comparisons are paired over identities and their 95 % intervals resample identities (:func:`summarise`); the
identity is the unit (its frames are not independent).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from bboxtune import filters
from bboxtune.agents.evaluation import stats
from bboxtune.envs.episodes.actions import TUNABLE
from bboxtune.envs.episodes.episode import Episode
from bboxtune.envs.episodes.scoring import run_tracks

WARMUP = 5  # frames after the first detection that are not scored on detected frames
N_BOOT = 2000  # bootstrap resamples of identities
Method = Callable[[list[Episode]], list[np.ndarray]]  # episodes → estimates (T_b, 4) cx, cy, w, h (NaN: none)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of (..., 4) cx, cy, w, h boxes row by row; NaN in either box gives 0 (no estimate is a failure)."""
    lo = np.maximum(a[..., :2] - a[..., 2:] / 2, b[..., :2] - b[..., 2:] / 2)
    hi = np.minimum(a[..., :2] + a[..., 2:] / 2, b[..., :2] + b[..., 2:] / 2)
    inter = np.prod(np.clip(hi - lo, 0.0, None), axis=-1)
    union = np.prod(np.clip(a[..., 2:], 0.0, None), axis=-1) + np.prod(np.clip(b[..., 2:], 0.0, None), axis=-1) - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(union > 0, inter / union, 0.0)
    return np.nan_to_num(np.minimum(out, 1.0), nan=0.0)


@dataclass(frozen=True)
class FrameSets:
    """The scored frames of one episode (bool (T,) masks)."""

    detected: np.ndarray
    gaps: np.ndarray


def frame_sets(episode: Episode) -> FrameSets:
    """The detected frames from :data:`WARMUP` after the first detection on, and the gap frames (module docstring)."""
    measured = np.isfinite(episode.y).all(axis=1)
    has_truth = np.isfinite(episode.truth).all(axis=1)
    index = np.arange(len(measured))
    first, last = (np.flatnonzero(measured)[[0, -1]] if measured.any() else (len(measured), -1))
    detected = measured & has_truth & (index >= first + WARMUP)
    gaps = ~measured & has_truth & (index > first) & (index < last)
    return FrameSets(detected=detected, gaps=gaps)


def identity_scores(estimate: np.ndarray, episode: Episode) -> dict[str, float]:
    """Scores of ``estimate`` (T, 4) on one identity (module docstring); NaN means where a set is empty."""
    sets = frame_sets(episode)
    iou = box_iou(estimate, episode.truth)
    squared = np.sum((estimate - episode.truth) ** 2, axis=1)
    n_det = int(sets.detected.sum())
    return {
        "iou_detected": float(iou[sets.detected].mean()) if n_det else np.nan,
        "sq_detected": float(squared[sets.detected].mean()) if n_det else np.nan,
        "iou_gap_sum": float(iou[sets.gaps].sum()),
        "n_gap": float(sets.gaps.sum()),
    }


def score_method(method: Method, episodes: list[Episode]) -> dict[str, np.ndarray]:
    """:func:`identity_scores` of ``method`` on every episode, each key an array over the episodes."""
    estimates = method(episodes)
    rows = [identity_scores(e, ep) for e, ep in zip(estimates, episodes, strict=False)]
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def raw_method(episodes: list[Episode]) -> list[np.ndarray]:
    """The detections themselves (nothing inside gaps)."""
    return [ep.y for ep in episodes]


def backend_method(backend: str, params: dict[str, float] | None = None) -> Method:
    """Back end ``backend`` with the same ``params`` (names it accepts) on every identity (default: its own
    defaults; the published weights for ``bytetrack_kf``, SORT's constants for ``sort_kf``)."""
    def run(episodes: list[Episode]) -> list[np.ndarray]:
        fixed = {k: np.full(len(episodes), float(v)) for k, v in (params or {}).items()}
        return filters.track_positions(backend, [ep.y for ep in episodes], [ep.tau for ep in episodes], fixed)
    return run


def rule_method(backend: str) -> Method:
    """The fixed rule on ``backend``: each episode's nominal parameters (N = N_opt and ψ nominal; the stock weights for
    ``bytetrack_kf``)."""
    def run(episodes: list[Episode]) -> list[np.ndarray]:
        params = {k: np.array([getattr(ep.nominal, k) for ep in episodes]) for k in TUNABLE}
        return run_tracks(backend, [ep.y for ep in episodes], [ep.tau for ep in episodes], params)
    return run


def paired_rows(scores: dict[str, dict[str, np.ndarray]], references: Sequence[str], seed: int = 0,
                n_boot: int = N_BOOT, clusters: Sequence[str] | None = None) -> list[dict[str, str]]:
    """One table row per method: mean IoU on detected frames, pooled IoU in gaps, log(RMSE_raw / RMSE), and the
    paired differences to each of ``references`` (method names), with 95 % identity-bootstrap intervals (with
    ``clusters``, one label per identity, e.g. its sequence: the clusters are resampled instead).
    Identities without scored detected frames are left out of the detected-frame columns (the same ones for
    every method)."""
    n = len(next(iter(scores.values()))["n_gap"])
    idx = (stats.bootstrap_indices(n, n_boot, seed) if clusters is None
           else stats.cluster_bootstrap_indices(clusters, n_boot, seed))
    ok = np.all([np.isfinite(s["iou_detected"]) for s in scores.values()], axis=0)
    raw_sq = scores["raw"]["sq_detected"]

    def mean_ci(x: np.ndarray, mask: np.ndarray) -> tuple[float, float, float]:
        masked = np.where(mask, x, 0.0)
        return stats.ci(np.stack([masked, mask.astype(float)]), lambda v: v[..., 0, :].sum(-1) / v[..., 1, :].sum(-1), idx)

    def pooled(s: dict[str, np.ndarray], ref: dict[str, np.ndarray] | None = None) -> tuple[float, float, float]:
        num = s["iou_gap_sum"] - (0.0 if ref is None else ref["iou_gap_sum"])
        return stats.ci(np.stack([num, s["n_gap"]]), lambda v: v[..., 0, :].sum(-1) / np.maximum(v[..., 1, :].sum(-1), 1), idx)

    rows = []
    for name, s in scores.items():
        row = {"method": name,
               "iou_detected": stats.fmt_ci(*mean_ci(s["iou_detected"], ok)),
               "iou_gaps": stats.fmt_ci(*pooled(s)),
               "log_rmse_ratio_vs_raw": stats.fmt_ci(*mean_ci(0.5 * np.log(raw_sq / s["sq_detected"]), ok), signed=True)}
        for ref in references:
            row[f"d_iou_detected_vs_{ref}"] = stats.fmt_ci(*mean_ci(s["iou_detected"] - scores[ref]["iou_detected"], ok),
                                                           signed=True)
            row[f"d_iou_gaps_vs_{ref}"] = stats.fmt_ci(*pooled(s, scores[ref]), signed=True)
        rows.append(row)
    return rows
