"""Figures of ``train.py`` (learning curve) and ``compare.py`` (log-ratio box plot, OTB-style success and
precision curves, example trajectories). Matplotlib with the non-interactive Agg back end; PNG files."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bboxtune.envs.data.metrics import PRECISION_THRESHOLDS, SUCCESS_THRESHOLDS  # noqa: E402


def _save(fig: plt.Figure, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def learning_curve(path: Path, timesteps: Sequence[int], rewards: Sequence[float], eval_timesteps: Sequence[int],
                   eval_results: Sequence[Sequence[float]], title: str) -> None:
    """Training reward (rolling mean over ~2 % of the episodes) and val-split evaluations (mean ± std/√n)."""
    fig, ax = plt.subplots(figsize=(7, 4))
    r = np.asarray(rewards, dtype=float)
    if len(r):
        w = max(1, min(len(r), len(r) // 50 or 1))
        smooth = np.convolve(r, np.ones(w) / w, mode="valid")
        ax.plot(np.asarray(timesteps)[w - 1:], smooth, lw=1, label=f"train episodes (rolling mean of {w})")
    if len(eval_timesteps):
        res = [np.asarray(e, dtype=float) for e in eval_results]
        m = np.array([e.mean() for e in res])
        se = np.array([e.std() / np.sqrt(len(e)) for e in res])
        ax.errorbar(eval_timesteps, m, yerr=1.96 * se, fmt="o-", ms=3, capsize=2, label="val split (mean, 95 % CI)")
    ax.axhline(0.0, color="k", lw=0.8, ls="--", label="fixed rule")
    ax.set_xlabel("timesteps (episodes)")
    ax.set_ylabel("reward = log(RMSE_rule / RMSE)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    _save(fig, path)


def gain_boxplot(path: Path, gains: dict[str, np.ndarray], title: str) -> None:
    """Box plot of the per-episode log(RMSE_rule / RMSE) of every method (> 0: better than the rule)."""
    names = list(gains)
    fig, ax = plt.subplots(figsize=(1.1 * len(names) + 2, 4))
    ax.boxplot([gains[n] for n in names], showfliers=False, whis=(5, 95))
    ax.set_xticks(range(1, len(names) + 1), names, rotation=30, ha="right")
    ax.axhline(0.0, color="k", lw=0.8, ls="--")
    ax.set_ylabel("log(RMSE_rule / RMSE)  (whiskers 5–95 %)")
    ax.set_title(title, fontsize=9)
    _save(fig, path)


def otb_curves(path: Path, success: dict[str, np.ndarray], precision: dict[str, np.ndarray], title: str) -> None:
    """OTB success plot (fraction of frames with IoU > t) and precision plot (centre error <= t px), each
    curve the mean over episodes; the legend holds the AUC and the precision at 20 px."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for name in success:
        s, p = success[name], precision[name]
        a.plot(SUCCESS_THRESHOLDS, s, label=f"{name} [{s.mean():.3f}]")
        b.plot(PRECISION_THRESHOLDS, p, label=f"{name} [{np.interp(20, PRECISION_THRESHOLDS, p):.3f}]")
    a.set(xlabel="IoU threshold", ylabel="success rate", title="success plot [AUC]")
    b.set(xlabel="centre error threshold (px)", ylabel="precision", title="precision plot [@20 px]")
    a.legend(fontsize=7)
    b.legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    _save(fig, path)


def trajectories(path: Path, truth: np.ndarray, y: np.ndarray, estimates: dict[str, np.ndarray], title: str,
                 frames: int = 200) -> None:
    """cx over the first ``frames`` frames of one episode: truth, measurements and each method's estimate."""
    n = min(frames, len(truth))
    fig, ax = plt.subplots(figsize=(9, 4))
    t = np.arange(n)
    ax.plot(t, y[:n, 0], ".", ms=2, color="0.6", label="measured")
    ax.plot(t, truth[:n, 0], "k-", lw=1.5, label="truth")
    for name, est in estimates.items():
        ax.plot(t, est[:n, 0], lw=1, label=name)
    ax.set(xlabel="frame", ylabel="cx (px)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, ncol=3)
    _save(fig, path)


def parameter_schedule(path: Path, schedules: dict[str, list[tuple[tuple[int, int], dict[str, float]]]],
                       scenario: dict, title: str) -> None:
    """One re-tuning episode: each method's parameters per window (steps over frames), one panel per parameter,
    with the true schedule behind them — noise-regime switches (vertical lines, the regime's ψ and σ_ξ written
    at its start), manoeuvre bursts (orange spans) and occlusion gaps (grey spans)."""
    keys = sorted({k for sched in schedules.values() for _, params in sched for k in params})
    fig, axes = plt.subplots(len(keys), 1, figsize=(8, 2.2 * len(keys) + 0.6), sharex=True, squeeze=False)
    for ax, key in zip(axes[:, 0], keys, strict=False):
        for name, sched in schedules.items():
            if not sched or key not in sched[0][1]:
                continue
            edges = [w[0] for w, _ in sched] + [sched[-1][0][1]]
            ax.stairs([p[key] for _, p in sched], edges, label=name, lw=1.4)
        for start, end in scenario.get("manoeuvres", []):
            ax.axvspan(start, end, color="tab:orange", alpha=0.15, lw=0)
        for start, end in scenario.get("gaps", []):
            ax.axvspan(start, end, color="0.5", alpha=0.3, lw=0)
        for regime in scenario.get("regimes", [])[1:]:
            ax.axvline(regime["start"], color="k", lw=0.8, ls="--")
        if key in ("horizon", "sigma_w", "sigma_v"):
            ax.set_yscale("log")
        ax.set_ylabel(key)
    for regime in scenario.get("regimes", []):
        axes[0, 0].annotate(f"ψ={regime['psi']:.2f}\nσξ={regime['sigma_xi']:.2g}", (regime["start"], 1.0),
                            xycoords=("data", "axes fraction"), va="bottom", fontsize=7)
    axes[-1, 0].set_xlabel("frame")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    fig.suptitle(title + "\n(dashed: noise-regime switches; orange: manoeuvres; grey: occlusion gaps)", fontsize=9)
    _save(fig, path)


def performance_profile(path: Path, taus: np.ndarray, curves: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, int]],
                        title: str) -> None:
    """Performance profiles (:func:`bboxtune.agents.evaluation.seeds_report.profile_curves`): the fraction of runs × tasks with a
    log-ratio above τ, per method, with its 95 % stratified bootstrap band."""
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, (curve, low, high, runs) in curves.items():
        ax.plot(taus, curve, label=f"{name} ({runs} runs)")
        ax.fill_between(taus, low, high, alpha=0.25)
    ax.set_xlabel("τ: log(RMSE_rule / RMSE)")
    ax.set_ylabel("fraction of runs × tasks with score > τ")
    ax.set_title(title, fontsize=8)
    ax.legend(fontsize=7)
    _save(fig, path)

