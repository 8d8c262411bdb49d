"""Shared pieces of the reproduction (``scripts/reproduce.py``, :mod:`bboxtune.agents.commands.reproduce`): run settings,
error measures, markdown tables and verdicts, figure output.

Every experiment module (:mod:`bboxtune.agents.reproduce.shmaliy_cmn`, :mod:`bboxtune.agents.reproduce.mo_fir`,
:mod:`bboxtune.agents.reproduce.otb`) returns a :class:`Section` (markdown text plus named matplotlib figures); the
command writes them. Files are written atomically (:mod:`bboxtune.envs.data.atomic_files`), so a killed run leaves either the
old file or the new one, never a part.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bboxtune import filters  # noqa: E402
from bboxtune.envs.data.atomic_files import atomic_write_file  # noqa: E402


@dataclass(frozen=True)
class Settings:
    """Monte Carlo sizes and grids of one reproduction run (``full`` or ``quick``)."""

    mc: int  # Monte Carlo tracks per grid point (simulations) / noise draws per OTB sequence
    seed: int  # base seed; experiment k draws from np.random.default_rng([seed, k])
    quick: bool  # coarse grids and few runs (the test's setting)
    fig2_psi: tuple[float, ...]  # ψ grid of [Shmaliy-CMN] Fig. 2
    nopt_psi: tuple[float, ...]  # ψ grid of the N_opt(ψ) search
    nopt_horizons: tuple[int, ...]  # candidate horizons N of the N_opt(ψ) search (frames)
    otb_horizons: tuple[int, ...]  # candidate horizons for the Car4 / Suv horizon sweeps (frames)
    fir_horizons: tuple[int, ...]  # Kwon FIR horizons of the [Mo-FIR] sweep (frames)
    otb_sigma_w: tuple[float, ...]  # px/s², σ_w grid of the KFs tuned on the OTB ground truth

    def rng(self, experiment: int) -> np.random.Generator:
        """Independent generator of experiment ``experiment`` (so experiments do not depend on their order)."""
        return np.random.default_rng([self.seed, experiment])


def make_settings(mc: int | None, seed: int, quick: bool) -> Settings:
    """The default grids (200 runs; ``quick``: coarse grids, 6 runs), ``mc`` overriding the number of runs."""
    if mc is not None and (not isinstance(mc, int) or mc < 2):
        raise ValueError(f"mc={mc!r} is out of range: allowed integers >= 2")
    if quick:
        return Settings(
            mc=mc or 6, seed=seed, quick=True,
            fig2_psi=(0.0, 0.3, 0.6, 0.8, 0.9, 0.95),
            nopt_psi=(0.0, 0.6, 0.95),
            nopt_horizons=(6, 10, 14, 20, 28, 40, 56, 80, 110, 150, 200),
            otb_horizons=(20, 40, 65, 100, 160, 240),
            fir_horizons=(10, 24, 50),
            otb_sigma_w=(3.0, 30.0, 300.0, 3000.0),
        )
    fine = np.arange(6, 41)
    coarse = np.unique(np.rint(np.geomspace(42, 250, 28)).astype(int))
    return Settings(
        mc=mc or 200, seed=seed, quick=False,
        fig2_psi=tuple(np.round(np.arange(0.0, 0.951, 0.05), 2).tolist()),
        nopt_psi=(0.0, 0.2, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95),
        nopt_horizons=tuple(int(n) for n in np.concatenate([fine, coarse])),
        otb_horizons=tuple(int(n) for n in np.unique(np.rint(np.geomspace(10, 320, 36)).astype(int))),
        fir_horizons=(6, 10, 16, 24, 36, 50, 75, 100),
        otb_sigma_w=tuple(np.round(np.geomspace(1.0, 10_000.0, 33), 3).tolist()),
    )


@dataclass
class Section:
    """One experiment's part of ``reproduction.md`` and its figures (file name → figure)."""

    title: str
    markdown: str
    figures: dict[str, plt.Figure] = field(default_factory=dict)


def pooled_rmse(est: np.ndarray, truth: np.ndarray, start: int = 0, axis: tuple[int, ...] = (-2, -1)) -> np.ndarray:
    """Root mean square of the Euclidean position error over frames ``start:`` (and tracks if ``axis`` says so).

    ``est``, ``truth`` (..., T, M) positions; NaN truth frames are left out; returns sqrt(mean_t Σ_c e²) reduced
    over ``axis`` (default: per track). Pooling tracks (``axis=(0, -2, -1)``) is the root of the mean MSE.
    A NaN estimate where the truth is finite is a ValueError (it would otherwise be skipped silently)."""
    truth = truth[..., start:, :]
    err = est[..., start:, :] - truth
    missing = np.isnan(truth).any(axis=-1, keepdims=True)
    sq = np.where(missing, np.nan, (err**2).sum(axis=-1, keepdims=True))  # Σ_c e² per frame (…, T, 1)
    if np.isnan(sq).sum() != np.broadcast_to(missing, sq.shape).sum():
        raise ValueError("est has NaN where the truth is finite; the filters promise finite output there")
    return np.sqrt(np.nanmean(sq, axis=axis))


def fmt(value: float, digits: int = 2) -> str:
    """A number for a markdown cell (``n/a`` for NaN)."""
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def md_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def verdict(agrees: bool, why: str, *, style: Literal["brackets", "colon"] = "brackets") -> str:
    """The verdict cell of a claim: ``agrees`` or ``**differs**``, then the reason ``why`` in brackets
    (``agrees (why)``) or, with ``style="colon"``, after a colon (``agrees: why``); an empty ``why`` gives the
    word alone. (The [Shmaliy-CMN] tables use the colon, the [Mo-FIR] and OTB tables the brackets.)

    >>> verdict(True, "counted above 1.5"), verdict(False, "x", style="colon"), verdict(True, "")
    ('agrees (counted above 1.5)', '**differs**: x', 'agrees')
    """
    word = "agrees" if agrees else "**differs**"
    if not why:
        return word
    return f"{word}: {why}" if style == "colon" else f"{word} ({why})"


def save_figure(fig: plt.Figure, path: Path) -> None:
    """Save ``fig`` as PNG atomically and close it."""
    atomic_write_file(path, lambda fh: fig.savefig(fh, format="png", dpi=110, bbox_inches="tight"))
    plt.close(fig)


def param_sweep(name: str, model: filters.StateSpaceModel, y: np.ndarray, param: str, values: Sequence[float] | np.ndarray,
                reduce: Callable[[np.ndarray], object], chunk_tracks: int = 2400, **fixed: object) -> np.ndarray:
    """Run back end ``name`` with ``param`` at every one of ``values`` on all tracks ``y`` (B, T, M); return
    ``reduce(states (B, T, K))`` per value, stacked (leading axis over ``values``). The values run as per-track
    parameter arrays on tiled copies of ``y``, about ``chunk_tracks`` tracks per filter call (bounds memory)."""
    values = np.asarray(values)
    per_call = max(1, chunk_tracks // y.shape[0])
    out = []
    for chunk in np.array_split(values, int(np.ceil(len(values) / per_call))):
        est = filters.make(name, model, **{param: np.repeat(chunk, y.shape[0])}, **fixed).run(
            np.tile(y, (len(chunk), 1, 1)))
        out += [reduce(states) for states in np.split(est, len(chunk))]
    return np.array(out)
