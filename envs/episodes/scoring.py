"""Run a back end on one episode for many candidate parameter sets at once, and score the estimates."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bboxtune import filters
from bboxtune.envs.data import metrics
from bboxtune.envs.data.memory import check_fits
from bboxtune.envs.episodes import scoring_kernels
from bboxtune.envs.episodes.actions import ACCEPTS
from bboxtune.filters import jit
from bboxtune.filters.bytetrack_kf import SIZE_MIN
from bboxtune.filters.threads import in_threads

SCORE_KEYS = ("rmse", "iou_mean", "success_auc", "precision20", "iou_precision")
# back ends that take boxes with w, h >= SIZE_MIN only (they filter the aspect w / h)
POSITIVE_SIZES = ("bytetrack_kf", "sort_kf")
# Peak memory of scoring candidates (run_positions + score_estimates) per candidate and frame, in bytes, with a 15 %
# margin (tracemalloc, FilterTune-v0 score of 200 candidates on a 200-frame episode; less per frame on longer episodes;
# tests/envs/test_memory.py). The numpy references: ukf 490, kf / kf_cmn 420, the FIR family 200-206, bytetrack_kf 155;
# the compiled kernels (bboxtune.filters.jit; the Kalman family's affine update without numpy temporaries): ukf 245,
# kf_cmn 173, the others as above.
CANDIDATE_FRAME_BYTES = {"ukf": 560, "kf": 480, "kf_cmn": 480}
CANDIDATE_FRAME_BYTES_COMPILED = {"ukf": 280}
CANDIDATE_FRAME_BYTES_OTHER = 240
# Scoring whose estimate is at most this many bytes is never refused and reads no memory figure: a step (1 candidate ×
# 500 frames needs at most 280 kB) would otherwise read /proc/meminfo every time (~50 µs, a tenth of a compiled step)
SMALL_SCORING_BYTES = 2**20


def candidate_frame_bytes(backend: str) -> int:
    """Peak bytes per candidate and frame of scoring candidates with ``backend`` (the kernels' or the references')."""
    table = CANDIDATE_FRAME_BYTES_COMPILED if jit.enabled() else CANDIDATE_FRAME_BYTES
    return table.get(backend, CANDIDATE_FRAME_BYTES_OTHER)


def box_model(tau: float) -> filters.StateSpaceModel:
    """The (cx, cy, w, h) constant-velocity model at frame interval ``tau`` (:func:`bboxtune.filters.constant_velocity`,
    which caches its models)."""
    return filters.constant_velocity(float(tau), ndim=4)


def _used(backend: str, params: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The parameters of the env's set (``bboxtune.envs.episodes.actions.TUNABLE``: psi, horizon, sigma_w, sigma_v and
    bytetrack_kf's weights) that ``backend`` takes (``ACCEPTS``)."""
    return {k: params[k] for k in ACCEPTS[backend]}


def detections(backend: str, y: np.ndarray) -> np.ndarray:
    """The measured boxes ``y`` (..., T, 4) as ``backend`` receives them: for :data:`POSITIVE_SIZES` a box with w or h
    below :data:`bboxtune.filters.bytetrack_kf.SIZE_MIN` is no detection (a NaN row: a detector reports no such box, and
    simulated noise can push a small box's measured size to or below 0); every other back end takes ``y`` as it is
    (the same array)."""
    small = (y[..., 2:] < SIZE_MIN).any(axis=-1) if backend in POSITIVE_SIZES else None  # NaN compares False
    if small is None or not small.any():
        return y
    out = y.copy()
    out[small] = np.nan
    return out


def run_positions(backend: str, y: np.ndarray, tau: float, params: dict[str, np.ndarray],
                  fixed: Mapping[str, float] | None = None) -> np.ndarray:
    """Filter the measured boxes ``y`` (T, 4) (as :func:`detections`) once per candidate: ``params`` maps names to
    arrays (A,); only the parameters ``backend`` accepts are passed, and ``fixed`` (parameters of ``backend`` outside
    the env's set, e.g. bytetrack_kf's gap policy) the same for every candidate. Returns position estimates
    (A, T, 4) cx, cy, w, h (:func:`bboxtune.filters.candidate_positions`, which also handles frame units)."""
    used = _used(backend, params)
    if fixed:
        n = len(next(iter(used.values()))) if used else 1
        used |= {k: np.full(n, float(v)) for k, v in fixed.items()}
    return filters.candidate_positions(backend, detections(backend, y), tau, used)


def check_candidates(backend: str, n_candidates: int, n_frames: int) -> None:
    """``bboxtune.envs.data.memory.MemoryLimitError`` (a ``ValueError`` naming ``actions``) when scoring ``n_candidates``
    actions on ``n_frames`` frames with ``backend`` would need more memory than this machine has available; an
    estimate of at most :data:`SMALL_SCORING_BYTES` (1 MiB) is accepted without reading the available memory."""
    needed = n_candidates * n_frames * candidate_frame_bytes(backend)
    if needed > SMALL_SCORING_BYTES:
        check_fits(needed, f"actions: {n_candidates} candidates × {n_frames} frames")


def run_tracks(backend: str, ys: list[np.ndarray], taus: list[float], params: dict[str, np.ndarray]) -> list[np.ndarray]:
    """Filter B tracks, each with its own parameter set: ``ys`` B arrays (T_b, 4), ``taus`` their frame
    intervals, ``params`` arrays (B,). Returns the position estimates, B arrays (T_b, 4), each equal to
    :func:`run_positions` on its track (:func:`bboxtune.filters.track_positions`: tracks of equal length share a call)."""
    return filters.track_positions(backend, [detections(backend, y) for y in ys], taus, _used(backend, params))


def run_track(backend: str, y: np.ndarray, tau: float, params: dict[str, np.ndarray]) -> np.ndarray:
    """``run_tracks(backend, [y], [tau], params)[0]`` for one track ``y`` (T, 4) and ``params`` arrays (1,), bit for
    bit, with the filter cached per parameter values (:func:`bboxtune.filters.one_track_positions`): a tuner's rule."""
    return filters.one_track_positions(backend, detections(backend, y), tau, _used(backend, params))


def hold_missing(est: np.ndarray, last: np.ndarray | None = None) -> np.ndarray:
    """Estimates (A, T, 4) with every missing row (any NaN) that follows an estimate replaced by the last estimate
    before it (held), as a display behind a tracker keeps showing the last box. ``last`` (4,): the estimate shown
    just before the first frame (a re-tuning window continuing a track), or None; rows before any estimate stay
    NaN (as they do when ``last`` is itself missing). An FIR filter has no estimate where its horizon holds too few
    measurements to determine the state (an occlusion gap longer than the horizon): held, such frames are scored
    like every other candidate's instead of being left out of that candidate's RMSE, which favoured short horizons
    through gaps."""
    ok = np.isfinite(est).all(axis=-1)  # (A, T)
    if ok.all():
        return est
    T = ok.shape[-1]
    source = np.maximum.accumulate(np.where(ok, np.arange(T), -1), axis=-1)  # the last row with an estimate
    out = np.take_along_axis(est, np.maximum(source, 0)[..., None], axis=-2)
    before = source < 0
    out[before] = np.nan if last is None else last
    return out


def score_estimates(est: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """Scores of estimates (A, T, 4) against the truth (T, 4) or (A, T, 4): :func:`score_estimates_numpy`'s, computed
    by the compiled kernel (:mod:`bboxtune.envs.episodes.scoring_kernels`) unless ``$BBOXTUNE_JIT=0``."""
    if not jit.enabled():
        return score_estimates_numpy(est, truth)
    e, g = np.asarray(est, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    if e.ndim != 3 or e.shape[-1] < 4 or g.ndim not in (2, 3) or g.shape[-2] != e.shape[1] or g.shape[-1] < 4 or \
            (g.ndim == 3 and g.shape[0] not in (1, e.shape[0])):
        raise ValueError(f"estimates {e.shape} and truth {g.shape}: allowed (A, T, 4) and (T, 4) or (A, T, 4)")
    A, T = e.shape[:2]
    per_row = g.ndim == 3 and g.shape[0] == A > 1
    lengths = np.full(A, T, dtype=np.int64)
    starts = np.arange(A, dtype=np.int64) * T
    truth_starts = starts if per_row else np.zeros_like(starts)
    return _scores(e.reshape(A * T, e.shape[-1]), g.reshape(-1, g.shape[-1]), starts, truth_starts, lengths)


def _scores(est: np.ndarray, truth: np.ndarray, est_starts: np.ndarray, truth_starts: np.ndarray,
            lengths: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`bboxtune.envs.episodes.scoring_kernels.score_segments` on rows (N, >= 4) of boxes, as a dict of SCORE_KEYS
    (many segments: in threads, each on its own segments)."""
    e, g = np.ascontiguousarray(est[:, :4]), np.ascontiguousarray(truth[:, :4])

    def score(part: slice) -> np.ndarray:
        return scoring_kernels.score_segments(e, g, est_starts[part], truth_starts[part], lengths[part],
                                              scoring_kernels.THRESHOLDS, scoring_kernels.RADIUS2)

    parts = in_threads(score, len(lengths), 4 * len(e) // max(len(lengths), 1))  # channel frames
    return dict(zip(SCORE_KEYS, np.concatenate(parts, axis=1) if len(parts) > 1 else parts[0], strict=True))


def score_estimates_numpy(est: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """Scores of estimates (A, T, 4) against the truth — (T, 4) shared by all rows (candidates on one
    episode) or (A, T, 4) (one episode per row) — all cx, cy, w, h; each value (A,).

    ``rmse``: sqrt(mean over frames of the squared Euclidean error of (cx, cy, w, h)) in px
    (:func:`bboxtune.envs.data.metrics.rmse_total`); ``iou_mean``; ``success_auc``, ``precision20`` and
    ``iou_precision`` ([PaleRamon-BBox]'s TP/(TP+FP), averaged over its 21 IoU thresholds) with the conventions of
    :mod:`bboxtune.envs.data.metrics` — computed here from one IoU and one centre-error pass (the tests check equality
    with the metric functions). Frames without ground truth are left out; a missing estimate where the
    truth exists counts as a failure (IoU 0, infinite centre error) and is not a detection, and is left
    out of the RMSE (filters have no estimate before a track's first finite measurement — the same frames
    for every candidate, so RMSEs stay paired)."""
    cx, cy, w, h = est[..., 0], est[..., 1], est[..., 2], est[..., 3]  # each (A, T)
    gx, gy, gw, gh = truth[..., 0], truth[..., 1], truth[..., 2], truth[..., 3]  # each (T,) or (A, T)
    valid = np.isfinite(gx) & np.isfinite(gy) & np.isfinite(gw) & np.isfinite(gh)
    scored = valid & np.isfinite(cx) & np.isfinite(cy) & np.isfinite(w) & np.isfinite(h)  # (A, T)
    everywhere = bool(scored.all())
    n = np.maximum(valid.sum(axis=-1), 1)  # frames with ground truth
    squared = (cx - gx) ** 2 + (cy - gy) ** 2 + (w - gw) ** 2 + (h - gh) ** 2  # (A, T), px²
    if everywhere:
        rmse = np.sqrt(squared.sum(axis=1) / squared.shape[1])
    else:
        n_scored = scored.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            rmse = np.where(n_scored > 0, np.sqrt(np.where(scored, squared, 0.0).sum(axis=1) / n_scored), np.nan)
    # IoU and centre error as bboxtune.envs.data.metrics computes them on xywh boxes (x = cx − w/2, widths clipped at 0)
    x, y = cx - 0.5 * w, cy - 0.5 * h
    gx0, gy0 = gx - 0.5 * gw, gy - 0.5 * gh
    wc, hc, gwc, ghc = np.maximum(w, 0.0), np.maximum(h, 0.0), np.maximum(gw, 0.0), np.maximum(gh, 0.0)
    iw = np.maximum(np.minimum(x + wc, gx0 + gwc) - np.maximum(x, gx0), 0.0)
    ih = np.maximum(np.minimum(y + hc, gy0 + ghc) - np.maximum(y, gy0), 0.0)
    inter = iw * ih
    union = wc * hc + gwc * ghc - inter
    overlap = np.zeros_like(inter)
    np.divide(inter, union, out=overlap, where=union > 0)  # (A, T)
    np.minimum(overlap, 1.0, out=overlap)  # rounding can give 1 + 1e-14 for equal boxes (as metrics.iou)
    dx, dy = (x + 0.5 * w) - (gx0 + 0.5 * gw), (y + 0.5 * h) - (gy0 + 0.5 * gh)
    within = dx * dx + dy * dy <= metrics.PRECISION_AT**2  # centre error <= 20 px
    if not everywhere:  # no truth: not counted; a missing estimate: IoU 0, never within the centre threshold
        overlap = np.where(scored, overlap, 0.0)
        within &= scored
    # per frame, the number of the 21 IoU thresholds below (success: IoU > t, strict as the OTB toolkit) and
    # at or below ([PaleRamon-BBox] true positive: IoU >= t) the frame's IoU; averaging these counts over frames and
    # thresholds is the mean over thresholds of the per-threshold rates
    thresholds = metrics.SUCCESS_THRESHOLDS
    below = np.searchsorted(thresholds, overlap, side="left")
    at_or_below = below + (thresholds[np.minimum(below, len(thresholds) - 1)] == overlap)
    if not everywhere:
        at_or_below = np.where(scored, at_or_below, 0)
    n_thresholds = len(thresholds)
    n_detected = scored.sum(axis=1)
    iou_precision = np.full(len(est), np.nan)  # NaN: no detection at all
    np.divide(at_or_below.sum(axis=1), n_thresholds * n_detected, out=iou_precision, where=n_detected > 0)
    return {
        "rmse": rmse,
        "iou_mean": overlap.sum(axis=1) / n,
        "success_auc": below.sum(axis=1) / (n_thresholds * n),
        "precision20": within.sum(axis=1) / n,
        "iou_precision": iou_precision,
    }


def score_tracks(estimates: list[np.ndarray], truths: list[np.ndarray]) -> dict[str, np.ndarray]:
    """:func:`score_estimates` of B tracks, each estimate (T_b, 4) against its own truth (T_b, 4); each value (B,),
    row b equal to scoring track b alone: one kernel call over all tracks (:func:`score_tracks_numpy` unless
    ``$BBOXTUNE_JIT=0``)."""
    if not jit.enabled():
        return score_tracks_numpy(estimates, truths)
    lengths = np.array([len(t) for t in truths], dtype=np.int64)
    if len(estimates) != len(truths) or any(len(e) != T for e, T in zip(estimates, lengths.tolist(), strict=False)):
        raise ValueError(f"{len(estimates)} estimates for {len(truths)} truths; allowed: one of each track's length per track")
    if not len(truths):
        return {k: np.empty(0) for k in SCORE_KEYS}
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    return _scores(_rows(estimates), _rows(truths), starts, starts, lengths)


def _rows(boxes: list[np.ndarray]) -> np.ndarray:
    """Arrays (T_b, >= 4) one after the other as C-contiguous float64 rows (ΣT_b, 4), whatever their layout."""
    out = np.empty((sum(len(b) for b in boxes), 4))
    return np.concatenate([b[:, :4] for b in boxes], axis=0, out=out)


def score_tracks_numpy(estimates: list[np.ndarray], truths: list[np.ndarray]) -> dict[str, np.ndarray]:
    """The numpy reference of :func:`score_tracks`: :func:`score_estimates_numpy` once per track length."""
    lengths = np.array([len(t) for t in truths])
    out = {k: np.empty(len(truths)) for k in SCORE_KEYS}
    for T in np.unique(lengths):
        rows = np.flatnonzero(lengths == T)
        scores = score_estimates_numpy(np.stack([estimates[r] for r in rows]), np.stack([truths[r] for r in rows]))
        for k in SCORE_KEYS:
            out[k][rows] = scores[k]
    return out


def reference_scores(baseline: str, rule_scores: dict[str, np.ndarray], ys: list[np.ndarray],
                     truths: list[np.ndarray]) -> dict[str, np.ndarray]:
    """The scores a FilterTune-v0 reward is measured against (``EnvConfig.reward_baseline``), each (B,): the
    rule's (``rule_scores``, returned as they are) or the unfiltered measurements' ``ys`` (B arrays (T_b, 4);
    a frame without a measurement is a missing estimate, as :func:`score_estimates` counts it)."""
    return rule_scores if baseline == "rule" else score_tracks(ys, truths)


def reward_label(kind: str, baseline: str = "rule") -> str:
    """What a reward of ``kind`` against ``baseline`` (``"rule"`` | ``"raw"``) measures, for printing."""
    return f"log(RMSE_{baseline}/RMSE)" if kind == "rmse" else f"{kind} minus the {baseline}'s"


def reward_from(scores: dict[str, np.ndarray], rule: dict[str, float] | dict[str, np.ndarray],
                kind: str) -> np.ndarray:
    """The env reward for candidates' ``scores`` against the reference's (``rule``: the rule's, or
    :func:`reference_scores`; floats, or arrays (B,) one per candidate's episode): ``rmse`` → log(RMSE_ref / RMSE)
    (scale-free: 0 = as good as the reference, +0.1 ≈ 10 % lower RMSE); ``iou_precision`` / ``success_auc`` →
    candidate minus reference."""
    if kind == "rmse":
        return np.log(rule["rmse"] / np.maximum(scores["rmse"], 1e-300))
    return scores[kind] - rule[kind]
