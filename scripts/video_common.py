"""Shared pieces of the video scripts (``track_video.py``, ``video_table.py``, ``video_camera.py``):
atomic output files and the paired bootstrap.

Every output is written to a temporary file in the destination folder and moved into place with
``os.replace``, so a killed run leaves either the previous file or the complete new one.
"""

from __future__ import annotations

import csv
import io
import json
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

import numpy as np  # noqa: E402


def write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """Call ``write(tmp)`` on a temporary path next to ``path``, then move it to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_text(path: Path, text: str) -> None:
    write_atomic(path, lambda p: p.write_text(text))


def write_json(path: Path, doc: Any) -> None:
    write_text(path, json.dumps(doc, indent=2, default=float) + "\n")


def write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    buf = io.StringIO()
    out = csv.writer(buf, lineterminator="\n")
    out.writerow(header)
    for row in rows:
        out.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in row])
    write_text(path, buf.getvalue())


def bootstrap_ci(diff: np.ndarray, rng: np.random.Generator, reps: int = 2000) -> tuple[float, float]:
    """95 % percentile bootstrap interval of the mean of paired differences ``diff`` (n,)."""
    diff = np.asarray(diff, dtype=float)
    means = diff[rng.integers(0, len(diff), (reps, len(diff)))].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)
