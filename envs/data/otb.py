"""OTB-100 sequences, attributes and real tracker outputs, from three layouts, plus the benchmark split.

Layouts (auto-detected by :class:`OTBDataset` from ``root``, else ``$OTB_ROOT``):

* ``"shared"`` — this project's layout (``shared/data/otb``): ``groundtruth/<Seq>.txt``, ``sequences.csv``
  (sequence, image_folder, n_frames, first_frame, …), ``attributes.csv`` (0/1 flags), optional
  ``trackers/<Tracker>/<Seq>.txt``. A table row repeating a sequence or naming one without a ground-truth
  file is an error naming the table and line; a folder, pipe or device where a file is expected is an error
  naming it.
* ``"folders"`` — the download from the OTB site: ``<Seq>/groundtruth_rect.txt``; two-target videos have
  ``groundtruth_rect.1.txt`` / ``.2.txt`` and become ``<Seq>-1`` / ``<Seq>-2`` (Jogging, Skating2, Human4 → only
  ``Human4-2``). Frame numbers follow the OTB toolkit: BlurCar1 starts at image 247, BlurCar3 at 3, BlurCar4 at
  18, David at 300, and the first 5 of Tiger1's 354 lines are skipped (its line 1 is then frame 6). No attributes.
* ``"pysot"`` — ``OTB100.json`` (``root`` may be the file or a folder holding it); keys video_dir, init_rect,
  img_names, gt_rect, attr; the first frame is the number in the first image name.

Ground truth is (T, 4) float xywh (1-based OTB pixels, unchanged); zero-size boxes are missing frames (NaN rows).
Tracker outputs are aligned line by line with the ground truth (row i = frame ``first_frame + i``).

Replay sources (episodes from OTB ground truth, as :class:`bboxtune.envs.data.simulate.Track` in (cx, cy, w, h) px, the
filters' ``ndim = 4`` measurements): (a) :func:`replay_synthetic`, synthetic CMN scaled to the box size; (b)
:func:`replay_tracker`, a real tracker's output as the measurement. Missing ground-truth rows are NaN in
``truth``. OTB has no velocity annotation: ``truth_state`` velocities are backward differences
(p_n − p_{n−1}) / τ, frame 0 copying frame 1 (NaN next to a missing frame); treat them as approximate.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from bboxtune.envs.data import textfile
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.envs.data.otb_io import csv_int, read_boxes, read_csv_table, read_pysot_json, video_of
from bboxtune.envs.data.simulate import Track, gauss_markov

logger = logging.getLogger(__name__)

OTB_ROOT_ENV = "OTB_ROOT"
ATTRIBUTES = ("IV", "SV", "OCC", "DEF", "MB", "FM", "IPR", "OPR", "OV", "BC", "LR")
_FOLDER_FIRST_FRAME = {"BlurCar1": 247, "BlurCar3": 3, "BlurCar4": 18, "David": 300}  # image of line 1
_TIGER1_OMIT = 5  # OTB toolkit initOmit: Tiger1's original 354-line file starts 5 frames early
_REPLAY_TAU = 0.05  # s, default sampling interval assumed by the filters ([Shmaliy-CMN] Car4 tuning: 20 frames/s)

# The default split of the 13 trackers under shared/data/otb/trackers (EnvConfig.trackers): "test" is held out,
# never trained on, so "unseen tracker" results exist — one of each kind: a strong Siamese tracker (SiamRPN++),
# a correlation-filter network (CFNet), a classic online SVM (STRUCK) and an online-learned CNN (MDNet).
TRACKER_SPLIT: dict[str, tuple[str, ...]] = {
    "train": ("ATOM", "DaSiamRPN", "MEEM", "MUSTer", "Ocean", "Ocean-online", "SiamBAN", "SiamFC", "SiamRPN"),
    "test": ("SiamRPN++", "CFNet", "STRUCK", "MDNet"),
}


@dataclass(frozen=True, eq=False)
class OTBSequence:
    """One annotated target: ground truth (T, 4) xywh with NaN rows for missing frames."""

    name: str  # e.g. "Jogging-1"
    video: str  # image folder it lives in, e.g. "Jogging" (targets of one video share the split)
    gt: np.ndarray  # (T, 4) xywh px, NaN = missing
    first_frame: int  # image number of row 0 (1-based)
    attributes: frozenset[str]  # OTB attribute flags, e.g. {"IV", "SV"}

    @property
    def n_frames(self) -> int:
        """Number of annotated frames T (missing ones included)."""
        return len(self.gt)


def resolve_root(root: str | os.PathLike | None) -> Path:
    """``root`` if given, else ``$OTB_ROOT``; ValueError when neither names an existing path."""
    return textfile.data_root(root, OTB_ROOT_ENV, "OTB")


def split(names: Iterable[str]) -> dict[str, tuple[str, ...]]:
    """Deterministic train / val / test split by video (never by window or by target of one video).

    Rule: b = int(first 8 bytes of SHA-256(lower-case video name), big-endian) mod 100; b < 60 → train,
    60 <= b < 80 → val, else test. A sequence's part depends only on its own video name (no seed, no other
    names), so subsets and other layouts agree. On OTB-100 this gives 55 / 22 / 23 sequences
    (55 / 21 / 22 videos).

    >>> split(["Jogging-1", "Jogging-2"])["train"] == split(["Jogging-2", "Jogging-1"])["train"]
    True
    """
    parts: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    for name in sorted(set(names)):
        digest = hashlib.sha256(video_of(name).lower().encode()).digest()
        bucket = int.from_bytes(digest[:8], "big") % 100
        parts["train" if bucket < 60 else "val" if bucket < 80 else "test"].append(name)
    return {k: tuple(v) for k, v in parts.items()}


def _normalise(name: str) -> str:
    return name.lower().replace("_", "-")


class OTBDataset:
    """OTB ground truth, attributes and tracker outputs under ``root`` (see the module docstring).

    ``trackers_root`` holds ``<Tracker>/<Seq>.txt`` files (default ``<root>/trackers``; file names match the
    sequence names ignoring case and with ``_`` read as ``-``)."""

    def __init__(self, root: str | os.PathLike | None = None, *, trackers_root: str | os.PathLike | None = None):
        self.root = resolve_root(root)
        self._cache: dict[str, OTBSequence] = {}
        self._meta: dict[str, dict] = {}
        if not self.root.is_dir() or (self.root / "OTB100.json").exists():
            self.layout = "pysot"
            self._load_pysot(self.root / "OTB100.json" if self.root.is_dir() else self.root)
        elif (self.root / "groundtruth").exists():
            self.layout = "shared"
            self._load_shared()
        else:
            self.layout = "folders"
            self._load_folders()
        self.names: tuple[str, ...] = tuple(sorted(self._meta))
        base = self.root if self.root.is_dir() else self.root.parent
        self.trackers_root = Path(trackers_root) if trackers_root is not None else base / "trackers"
        found = self.trackers_root.is_dir()
        if not found and (trackers_root is not None or self.trackers_root.exists()):
            raise ValueError(f"trackers_root {str(self.trackers_root)!r} is not a folder")
        self.trackers: tuple[str, ...] = tuple(
            sorted(p.name for p in self.trackers_root.iterdir() if p.is_dir()) if found else ()
        )
        self._tracker_files: dict[str, dict[str, Path]] = {}

    # --- layouts -------------------------------------------------------------------------------------------
    def _load_shared(self) -> None:
        gt_dir = self.root / "groundtruth"
        if not gt_dir.is_dir():
            raise ValueError(f"{gt_dir}: is not a folder (expected groundtruth/<Sequence>.txt files)")
        files = {p.stem: p for p in sorted(gt_dir.glob("*.txt"))}
        if not files:
            raise ValueError(f"{gt_dir}: no <Sequence>.txt ground-truth files")
        for path in files.values():
            if not path.is_file():
                raise ValueError(f"{path}: is not a regular file (expected a ground-truth text file)")
        table = self.root / "sequences.csv"
        info: dict[str, tuple[str, int, int]] = {}
        first_line: dict[str, int] = {}
        for line, row in read_csv_table(table, ("sequence", "n_frames", "first_frame")) if table.exists() else []:
            name = row["sequence"]
            if name in first_line:
                raise ValueError(f"{table}:{line}: duplicate row for sequence {name!r} (first at line "
                                 f"{first_line[name]})")
            if name not in files:
                raise ValueError(f"{table}:{line}: sequence {name!r} has no ground-truth file <name>.txt in {gt_dir}")
            first_line[name] = line
            info[name] = (row.get("image_folder") or video_of(name), csv_int(row, "n_frames", table, line, low=1),
                          csv_int(row, "first_frame", table, line, low=1))
        attributes = self._read_attributes(self.root / "attributes.csv", set(files))
        for name, path in files.items():
            video, n_frames, first = info.get(name, (video_of(name), None, 1))
            self._meta[name] = {"path": path, "n_expected": n_frames, "video": video, "first_frame": first,
                                "attributes": attributes.get(name, frozenset())}

    @staticmethod
    def _read_attributes(path: Path, names: set[str]) -> dict[str, frozenset[str]]:
        """Flags per sequence from ``attributes.csv`` (if present); every row names a known sequence once."""
        if not path.exists():
            return {}
        out: dict[str, frozenset[str]] = {}
        for line, row in read_csv_table(path, ("sequence",)):
            name = row["sequence"]
            if name in out or name not in names:
                problem = "a second row for" if name in out else "no ground-truth file for"
                raise ValueError(f"{path}:{line}: {problem} sequence {name!r}")
            flags = [a for a in ATTRIBUTES if a in row]
            bad = [a for a in flags if row[a] not in ("0", "1")]
            if bad:
                raise ValueError(f"{path}:{line}: attribute {bad[0]}={row[bad[0]]!r}; allowed 0 or 1")
            out[name] = frozenset(a for a in flags if row[a] == "1")
        return out

    def _load_folders(self) -> None:
        for folder in sorted(p for p in self.root.iterdir() if p.is_dir()):
            for path in sorted(folder.glob("groundtruth_rect*.txt")):
                match = re.fullmatch(r"groundtruth_rect(?:\.([0-9]+))?\.txt", path.name)  # linear: no nesting
                if match is None:
                    continue
                name = folder.name if match.group(1) is None else f"{folder.name}-{match.group(1)}"
                self._meta[name] = {"path": path, "n_expected": None, "video": folder.name,
                                    "first_frame": _FOLDER_FIRST_FRAME.get(folder.name, 1),
                                    "attributes": frozenset()}
        if not self._meta:
            raise ValueError(
                f"{self.root}: no OTB layout found: expected OTB100.json, groundtruth/<Seq>.txt, "
                "or <Seq>/groundtruth_rect.txt folders"
            )

    def _load_pysot(self, path: Path) -> None:
        for name, entry in read_pysot_json(path).items():
            self._meta[name] = {"path": path, **entry}
            self._cache[name] = OTBSequence(name=name, video=entry["video"], gt=entry["gt"],
                                            first_frame=entry["first_frame"], attributes=entry["attributes"])

    # --- sequences ----------------------------------------------------------------------------------------
    def _check_name(self, name: str) -> None:
        if name not in self._meta:
            raise ValueError(f"unknown sequence {name!r}; {len(self.names)} sequences under {self.root}")

    def sequence(self, name: str) -> OTBSequence:
        """The sequence ``name`` (ground truth read on first use, then cached)."""
        self._check_name(name)
        if name not in self._cache:
            meta = self._meta[name]
            gt, first = read_boxes(meta["path"], n_expected=meta["n_expected"]), meta["first_frame"]
            if self.layout == "folders" and meta["video"] == "Tiger1" and len(gt) == 354:
                gt, first = gt[_TIGER1_OMIT:], first + _TIGER1_OMIT
            self._cache[name] = OTBSequence(name=name, video=meta["video"], gt=gt, first_frame=first,
                                            attributes=meta["attributes"])
        return self._cache[name]

    def groundtruth(self, name: str) -> np.ndarray:
        """(T, 4) xywh ground truth of ``name``; NaN rows are missing frames."""
        return self.sequence(name).gt

    # --- trackers -----------------------------------------------------------------------------------------
    def _files(self, tracker: str) -> dict[str, Path]:
        if tracker not in self.trackers:
            raise ValueError(f"unknown tracker {tracker!r}; found {list(self.trackers)} in {self.trackers_root}")
        if tracker not in self._tracker_files:
            listing: dict[str, Path] = {}
            for path in sorted((self.trackers_root / tracker).glob("*.txt")):
                if _normalise(path.stem) in listing:
                    raise ValueError(f"{path}: same sequence as {listing[_normalise(path.stem)].name} (names "
                                     "match ignoring case and '_' vs '-'); keep one file per sequence")
                listing[_normalise(path.stem)] = path
            self._tracker_files[tracker] = {
                n: listing[_normalise(n)] for n in self.names if _normalise(n) in listing
            }
        return self._tracker_files[tracker]

    def tracker_sequences(self, tracker: str) -> tuple[str, ...]:
        """Sequences for which ``tracker`` has an output file."""
        return tuple(self._files(tracker))

    def tracker_boxes(self, tracker: str, name: str, *, strict: bool = False) -> np.ndarray:
        """``tracker``'s (T, 4) xywh output on ``name``, row-aligned with :meth:`groundtruth`.

        A file with more boxes than the ground truth is a ValueError. A shorter file is padded with NaN rows
        (missing predictions, scored as failures) and logged naming the file (a warning when any padded frame
        has ground truth, else INFO: MDNet lacks the unannotated last frame of Board and Twinnings); with
        ``strict=True`` it is a ValueError instead. Zero-size output boxes are NaN rows too."""
        files = self._files(tracker)
        if name not in files:
            self._check_name(name)
            raise ValueError(f"tracker {tracker!r} has no output for {name!r} in {self.trackers_root / tracker}")
        path, n_gt = files[name], self.sequence(name).n_frames
        boxes = read_boxes(path)
        if len(boxes) > n_gt or (strict and len(boxes) < n_gt):
            raise ValueError(f"{path}:{min(len(boxes), n_gt) + 1}: file has {len(boxes)} boxes, "
                             f"ground truth has {n_gt}")
        if len(boxes) < n_gt:
            scored = int((~np.isnan(self.groundtruth(name)[len(boxes):]).any(axis=1)).sum())
            logger.log(logging.WARNING if scored else logging.INFO,
                       "%s: %d boxes for %d ground-truth frames; the last %d are missing predictions "
                       "(%d of them have ground truth and score as failures)",
                       path, len(boxes), n_gt, n_gt - len(boxes), scored)
            boxes = np.concatenate([boxes, np.full((n_gt - len(boxes), 4), np.nan)])
        return boxes


# --- replay sources --------------------------------------------------------------------------------------------
def _gt_boxes(gt_xywh: ArrayLike) -> np.ndarray:
    gt = np.asarray(gt_xywh, dtype=float)
    if gt.ndim != 2 or gt.shape[1] != 4 or len(gt) < 2:
        raise ValueError(f"gt_xywh has shape {gt.shape}; allowed (T, 4) with T >= 2")
    if np.any(np.isinf(gt)) or np.any(gt[:, 2:] <= 0):
        raise ValueError("gt_xywh must hold finite boxes with w, h > 0, or NaN rows for missing frames")
    return gt


def _check_tau(tau: float) -> float:
    if not (np.isfinite(tau) and tau > 0):
        raise ValueError(f"tau={tau!r} is out of range: allowed finite values > 0")
    return float(tau)


def _track(truth: np.ndarray, y: np.ndarray, tau: float) -> Track:
    velocity = np.empty_like(truth)
    velocity[1:] = np.diff(truth, axis=0) / tau  # backward differences
    velocity[0] = velocity[1]
    return Track(truth=truth, truth_state=np.concatenate([truth, velocity], axis=1), y=y, tau=tau)


def replay_synthetic(
    gt_xywh: ArrayLike, *, psi: float, sigma_rel: float, rng: np.random.Generator, tau: float = _REPLAY_TAU
) -> Track:
    """Source (a): OTB ground truth as the truth, plus Gauss–Markov CMN scaled to the true box size.

    A dimensionless CMN u_n = ψ u_{n−1} + ξ_n, ξ_n ~ N(0, sigma_rel²) (stationary start, one independent
    channel per coordinate) is scaled per frame by the true box:

        cx_meas = cx + w·u_cx,   cy_meas = cy + h·u_cy,   w_meas = w·exp(u_w),   h_meas = h·exp(u_h)

    so the centre noise is a fixed fraction of the box size (sigma_rel = 0.05: ξ std of 5 % of w, h) and
    measured sizes stay positive (log-normal; E[exp(u)] = exp(var u / 2), a 0.5 % bias at std(u) = 0.1)."""
    gt = _gt_boxes(gt_xywh)
    if not (np.isfinite(psi) and 0 <= psi < 1):
        raise ValueError(f"psi={psi!r} is out of range: allowed 0 <= psi < 1")
    if not (np.isfinite(sigma_rel) and sigma_rel > 0):
        raise ValueError(f"sigma_rel={sigma_rel!r} is out of range: allowed finite values > 0")
    truth = xywh_to_cxcywh(gt)
    u = gauss_markov(float(psi), np.full(4, float(sigma_rel)), (1, len(gt), 4), rng)[0]
    y = np.concatenate([truth[:, :2] + truth[:, 2:] * u[:, :2], truth[:, 2:] * np.exp(u[:, 2:])], axis=1)
    return _track(truth, y, _check_tau(tau))


def replay_tracker(gt_xywh: ArrayLike, measured_xywh: ArrayLike, *, tau: float = _REPLAY_TAU) -> Track:
    """Source (b): OTB ground truth as the truth and a real tracker's output as the measurement.

    ``measured_xywh`` (T, 4) is row-aligned with the ground truth (as :meth:`OTBDataset.tracker_boxes`
    returns it); its NaN rows are missing detections. A tracker box on a frame without ground truth is kept
    as a measurement (the filter may use it; the frame is simply not scored)."""
    gt = _gt_boxes(gt_xywh)
    meas = np.asarray(measured_xywh, dtype=float)
    if meas.shape != gt.shape:
        raise ValueError(f"measured_xywh has shape {meas.shape}; it must match gt_xywh {gt.shape}")
    if np.any(np.isinf(meas)):
        raise ValueError("measured_xywh contains ±inf; allowed finite values or NaN rows for missing frames")
    truth = xywh_to_cxcywh(gt)
    return _track(truth, xywh_to_cxcywh(meas), _check_tau(tau))
