"""Smoothing MOT-format tracks with a learned tuner, one identity at a time (``scripts/smooth.py --format mot``).

Conventions (as in :mod:`bboxtune.envs.data.mot_io`): frames are 1-based; boxes are xywh in px, (x, y) the top-left corner;
a MOT result line is ``frame, id, x, y, w, h, score, X, Y, Z`` (trackers write -1 for X, Y, Z).

* **Input** (:func:`read_inputs`): a MOT result file, a folder of ``<Sequence>.txt`` result files, or a MOT
  sequence folder holding ``det/det.txt`` and ``gt/gt.txt`` (MOT15 layout), whose public detections are matched
  to the ground-truth identities (:func:`bboxtune.envs.data.mot.match_identities`): each matched detection is a row
  ``frame, ground-truth id, the detection's box, the detection's score``; unmatched detections are not written
  (counted). Malformed files are ValueErrors naming ``file:line`` (the :mod:`bboxtune.envs.data.mot_io` readers).
* **Tracks** (:class:`IdentityTrack`): the rows of one id, from its first to its last frame; frames in between
  without a row are gaps (NaN rows of ``boxes``). The tracks of one file may span at most :data:`MAX_SPAN_FRAMES`
  frames in all (the output's row bound).
* **Smoothing** (:func:`smooth_track`): each track on its own, with the parameters the tuner chooses from that
  track's boxes alone (:meth:`bboxtune.agents.smoothing.tuner.Tuner.observe`, ``params``, ``smooth``). A track
  shorter than the tuner's
  minimum (:data:`bboxtune.agents.smoothing.tuner.MIN_FRAMES` frames,
  :data:`bboxtune.agents.smoothing.tuner.MIN_MEASURED` rows) is not
  tuned, and a track
  where a gated tuner's gate stays closed is not smoothed: both are written as read.
* **Output rows** (:func:`track_rows`, :func:`file_text`): a smoothed track gets one row per frame of its span,
  ``frame, id, x, y, w, h, score, -1, -1, -1`` with the back end's box to 3 decimals; a row of the input keeps its
  score (the value as read), a filled gap row has score ``-1``; a box whose w or h is <= 0 at 3 decimals is not
  written (counted). A track written as read keeps its input lines byte for byte (line ends become ``\\n``; a
  sequence folder's rows are written from the values read: ``frame, id, x, y, w, h, score, -1, -1, -1``, shortest
  exact numbers). Rows are sorted by frame, then id.
* **Frame rate** (:func:`frame_rates`): ``--fps``, else ``frameRate=`` of section ``[Sequence]`` of the
  ``seqinfo.ini`` in the input file's folder or the folder above it (a sequence folder's ``det/`` or the sequence
  folder itself), else the ``fps`` of the sequence's row in ``<MOT root>/sequences.csv``; τ = 1 / fps must lie in
  :data:`bboxtune.agents.smoothing.tuner.TAU_RANGE` (:data:`FPS_RANGE`).
"""

from __future__ import annotations

import configparser
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bboxtune.agents.smoothing.stock_filter import TrackSmoother
from bboxtune.agents.smoothing.tuner import MIN_FRAMES, MIN_MEASURED, TAU_RANGE
from bboxtune.envs.data import textfile
from bboxtune.envs.data.mot import match_identities, resolve_root
from bboxtune.envs.data.mot_io import (
    Results,
    SequenceInfo,
    read_detections,
    read_ground_truth,
    read_results,
    read_sequences_csv,
)
from bboxtune.envs.data.number_grammar import parse_float, shorten
from bboxtune.envs.data.otb_io import read_text

MAX_SPAN_FRAMES = 5_000_000  # output rows of one file at most (first to last frame of every track, summed)
FPS_RANGE = (1.0 / TAU_RANGE[1], 1.0 / TAU_RANGE[0])  # frames per second: 1..1000
SEQINFO = "seqinfo.ini"
SEQINFO_MAX_BYTES = 64 * 2**10  # a MOT seqinfo.ini has about 150 bytes
FILLED_SCORE = "-1"  # the score of a filled gap row


@dataclass(frozen=True, eq=False)
class IdentityTrack:
    """The rows of one id from its first to its last frame."""

    identity: int
    first_frame: int  # 1-based frame of row 0
    boxes: np.ndarray  # (T, 4) xywh px; NaN rows: gaps (frames without a row)
    scores: np.ndarray  # (T,) the rows' scores; NaN in gaps
    lines: tuple[str, ...]  # the rows as read, in frame order (one per finite row of ``boxes``)

    @property
    def n_frames(self) -> int:
        return len(self.boxes)

    @property
    def n_rows(self) -> int:
        return len(self.lines)

    @property
    def too_short(self) -> bool:
        """Shorter than the tuner's minimum: not tuned, written as read."""
        return self.n_frames < MIN_FRAMES or self.n_rows < MIN_MEASURED


@dataclass(frozen=True, eq=False)
class MOTInput:
    """One input: a result file or a sequence folder's matched detections, split into tracks."""

    name: str  # output file name, <sequence>.txt
    path: Path  # the file read (a result file, or the sequence folder's det/det.txt)
    tracks: tuple[IdentityTrack, ...]  # by id
    n_unmatched: int = 0  # sequence folder: detections matched to no identity (not written)

    @property
    def sequence(self) -> str:
        return Path(self.name).stem


def exact(value: float) -> str:
    """``value`` as the shortest text that reads back to it (``3``, ``0.25``, ``1e-05``)."""
    return str(int(value)) if value.is_integer() and abs(value) < 1e18 else repr(float(value))


def split_tracks(rows: Results, lines: Sequence[str], source: str) -> tuple[IdentityTrack, ...]:
    """The tracks of ``rows`` (row i written as ``lines[i]``), by id; ValueError naming ``source`` when they span
    more than :data:`MAX_SPAN_FRAMES` frames in all."""
    if not len(rows):
        return ()
    order = np.lexsort((rows.frame, rows.id))
    ids = rows.id[order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    ends = np.r_[starts[1:], len(order)]
    spans = rows.frame[order[ends - 1]] - rows.frame[order[starts]] + 1
    if spans.sum() > MAX_SPAN_FRAMES:
        raise ValueError(f"{source}: its {len(starts)} tracks span {int(spans.sum())} frames in all (first to last "
                         f"frame of each id); allowed at most {MAX_SPAN_FRAMES}")
    out = []
    for start, end, span in zip(starts, ends, spans, strict=True):
        picked = order[start:end]
        at = rows.frame[picked] - rows.frame[picked[0]]
        boxes, scores = np.full((span, 4), np.nan), np.full(span, np.nan)
        boxes[at], scores[at] = rows.box[picked], rows.score[picked]
        out.append(IdentityTrack(identity=int(ids[start]), first_frame=int(rows.frame[picked[0]]), boxes=boxes,
                                 scores=scores, lines=tuple(lines[i] for i in picked)))
    return tuple(out)


def read_result_file(path: Path) -> MOTInput:
    """A MOT result file (``frame, id, x, y, w, h, score, X, Y, Z`` per line) as :class:`MOTInput`."""
    rows = read_results(path)
    lines = read_text(path).split("\n")[:len(rows)]  # read as the reader does: row i is line i + 1
    return MOTInput(name=path.name, path=path, tracks=split_tracks(rows, lines, str(path)))


def read_sequence_folder(folder: Path) -> MOTInput:
    """A MOT sequence folder's public detections matched to its ground-truth identities (module docstring), as
    the result file ``<folder name>.txt``."""
    det_path, gt_path = folder / "det" / "det.txt", folder / "gt" / "gt.txt"
    for path in (det_path, gt_path):
        if not path.exists():
            raise ValueError(f"{folder} has no {path.relative_to(folder)}; a sequence folder holds det/det.txt (public "
                             f"detections) and gt/gt.txt (the identities they are matched to)")
    det, gt = read_detections(det_path), read_ground_truth(gt_path)
    det_of_gt = match_identities(det, gt)
    hit = np.flatnonzero(det_of_gt >= 0)
    matched = det_of_gt[hit]
    rows = Results(frame=gt.frame[hit], id=gt.id[hit], box=det.box[matched], score=det.score[matched])
    lines = [",".join([str(f), str(i), *map(exact, box), exact(s), "-1,-1,-1"])
             for f, i, box, s in zip(rows.frame, rows.id, rows.box, rows.score, strict=True)]
    name = f"{Path(os.path.abspath(folder)).name}.txt"
    return MOTInput(name=name, path=det_path, tracks=split_tracks(rows, lines, str(det_path)),
                    n_unmatched=len(det) - len(hit))


def read_inputs(path: Path) -> list[MOTInput]:
    """The inputs at ``path`` (module docstring): a result file; a sequence folder (one with ``det/det.txt`` or
    ``gt/gt.txt``); else a folder's ``*.txt`` result files, by name. ValueError naming the file at fault."""
    if not path.is_dir():
        return [read_result_file(path)]
    if (path / "det" / "det.txt").exists() or (path / "gt" / "gt.txt").exists():
        return [read_sequence_folder(path)]
    files = sorted(p for p in path.iterdir() if p.suffix == ".txt")
    if not files:
        raise ValueError(f"{path} holds neither MOT result files <Sequence>.txt nor a sequence's det/det.txt and "
                         "gt/gt.txt")
    return [read_result_file(p) for p in files]


# --- frame rate ------------------------------------------------------------------------------------------------
def check_fps(fps: float, source: str) -> float:
    """``fps`` if finite and in :data:`FPS_RANGE` (τ = 1/fps in the tuner's range); else ValueError naming
    ``source``."""
    low, high = FPS_RANGE
    if not (np.isfinite(fps) and low <= fps <= high):
        raise ValueError(f"{source}: frame rate {fps:g}; allowed {low:g} <= fps <= {high:g} (tau = 1/fps in "
                         f"[{TAU_RANGE[0]:g}, {TAU_RANGE[1]:g}] s)")
    return float(fps)


def _ini_error(path: Path, err: configparser.Error) -> str:
    """A one-line ``file:line: why`` for a configparser error."""
    if isinstance(err, configparser.MissingSectionHeaderError):
        return f"{path}:{err.lineno}: text before the first [section] header: {shorten(err.line.strip())}"
    if isinstance(err, configparser.DuplicateOptionError):
        return f"{path}:{err.lineno}: {err.option!r} repeated in section [{err.section}]"
    if isinstance(err, configparser.DuplicateSectionError):
        return f"{path}:{err.lineno}: section [{err.section}] repeated"
    if isinstance(err, configparser.ParsingError) and err.errors:
        lineno, line = err.errors[0]  # line: its repr
        return f"{path}:{lineno}: expected key=value, [section] or a comment, got {line[:60]}"
    return f"{path}: invalid ini file ({' '.join(str(err).split())})"


def read_seqinfo_fps(path: Path) -> float:
    """``frameRate=`` of section ``[Sequence]`` of the ``seqinfo.ini`` at ``path`` (bounded read, strict ini:
    no repeated section or key, no interpolation); ValueError naming the file (and line)."""
    ini = configparser.ConfigParser(interpolation=None)
    try:
        ini.read_string(textfile.read_text(path, SEQINFO_MAX_BYTES), source=str(path))
    except configparser.Error as err:
        raise ValueError(_ini_error(path, err)) from None
    if not ini.has_option("Sequence", "frameRate"):
        raise ValueError(f"{path}: no frameRate= in section [Sequence]; pass --fps F")
    value = ini.get("Sequence", "frameRate")
    try:
        fps = parse_float(value.strip())
    except ValueError:
        raise ValueError(f"{path}: frameRate={shorten(value)} is not a number") from None
    return check_fps(fps, f"{path}: frameRate")


def find_seqinfo(path: Path) -> Path | None:
    """The ``seqinfo.ini`` in the folder of the file ``path``, else in the folder above it; None if neither."""
    folder = Path(os.path.abspath(path.parent))
    return next((f / SEQINFO for f in (folder, folder.parent) if os.path.lexists(f / SEQINFO)), None)


@dataclass(frozen=True)
class FrameRate:
    fps: float
    source: str  # "--fps", a seqinfo.ini or a sequences.csv


def frame_rates(inputs: Sequence[MOTInput], fps: float | None, mot_root: str | os.PathLike | None) -> list[FrameRate]:
    """The frame rate of each input (module docstring): ``fps`` if given, else its ``seqinfo.ini``, else the
    sequences.csv of ``mot_root`` (None: none). ValueError naming the file at fault, or saying to pass --fps."""
    if fps is not None:
        return [FrameRate(check_fps(fps, "--fps"), "--fps")] * len(inputs)
    table: dict[str, SequenceInfo] | None = None
    out = []
    for item in inputs:
        ini = find_seqinfo(item.path)
        if ini is not None:
            out.append(FrameRate(read_seqinfo_fps(ini), str(ini)))
            continue
        folder = Path(os.path.abspath(item.path.parent))
        missing = f"no frame rate for {item.sequence}: no {SEQINFO} in {folder} or {folder.parent}"
        if mot_root is None:
            raise ValueError(f"{missing}, and no MOT root (--mot-root, $MOT_ROOT) with a sequences.csv; pass --fps F")
        root = resolve_root(mot_root)
        table = read_sequences_csv(root) if table is None else table
        if item.sequence not in table:
            raise ValueError(f"{missing}, and {root / 'sequences.csv'} has no row {item.sequence!r}; pass --fps F")
        out.append(FrameRate(check_fps(float(table[item.sequence].fps), str(root / "sequences.csv")),
                             str(root / "sequences.csv")))
    return out


# --- smoothing and output --------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Smoothed:
    """A track and what the tuner made of it."""

    track: IdentityTrack
    boxes: np.ndarray | None  # (T, 4) xywh px, the back end's estimates; None: written as read
    params: dict[str, float | int] | None  # the parameters the tuner chose; None: too short to tune

    @property
    def left_alone(self) -> bool:
        return self.boxes is None


def smooth_track(tuner: TrackSmoother[Any], track: IdentityTrack, tau: float) -> Smoothed:
    """``track`` smoothed with the parameters ``tuner`` chooses from its boxes alone (module docstring)."""
    if track.too_short:
        return Smoothed(track, None, None)
    seen = tuner.observe(track.boxes, tau)
    params = tuner.params(seen)
    if tuner.leaves_alone(seen):
        return Smoothed(track, None, params)
    return Smoothed(track, tuner.smooth(track.boxes, tau, params), params)


@dataclass(frozen=True)
class Rows:
    """The output rows of one track."""

    identity: int
    frame: np.ndarray  # (n,) int64
    lines: list[str]
    n_filled: int  # gap rows written
    n_dropped: int  # smoothed boxes not written (w or h <= 0 at 3 decimals, or no estimate)


def track_rows(smoothed: Smoothed) -> Rows:
    """The MOT result rows of a smoothed track (module docstring)."""
    track = smoothed.track
    measured = np.isfinite(track.boxes).all(axis=1)
    frames = track.first_frame + np.arange(track.n_frames, dtype=np.int64)
    if smoothed.boxes is None:
        return Rows(track.identity, frames[measured], list(track.lines), 0, 0)
    boxes = smoothed.boxes
    written = np.isfinite(boxes).all(axis=1) & (np.round(boxes[:, 2:], 3) > 0).all(axis=1)
    lines = [",".join([str(frames[t]), str(track.identity), *(f"{v:.3f}" for v in boxes[t]),
                       exact(track.scores[t]) if measured[t] else FILLED_SCORE, "-1,-1,-1"])
             for t in np.flatnonzero(written)]
    return Rows(track.identity, frames[written], lines, int((written & ~measured).sum()), int((~written).sum()))


def file_text(tracks: Sequence[Rows]) -> str:
    """The text of a MOT result file of the rows of ``tracks``, sorted by frame, then id."""
    frames = np.concatenate([np.empty(0, dtype=np.int64), *(rows.frame for rows in tracks)])
    ids = np.concatenate([np.empty(0, dtype=np.int64), *(np.full(len(rows.lines), rows.identity) for rows in tracks)])
    lines = [line for rows in tracks for line in rows.lines]
    return "".join(lines[i] + "\n" for i in np.lexsort((ids, frames)))


def params_header(backend_params: Sequence[str]) -> list[str]:
    """params.csv's columns for a back end taking ``backend_params``."""
    return ["file", "identity", "fps", "n_frames", "n_rows_in", "n_filled", "n_dropped", "left_alone",
            *backend_params]


def params_row(name: str, fps: float, smoothed: Smoothed, rows: Rows, backend_params: Sequence[str]) -> list:
    """One params.csv row: the counts and the chosen parameters (exact; empty for a track too short to tune)."""
    track = smoothed.track
    params = smoothed.params
    chosen = [str(params[k]) for k in backend_params] if params is not None else [""] * len(backend_params)
    return [name, track.identity, fps, track.n_frames, track.n_rows, rows.n_filled, rows.n_dropped,
            int(smoothed.left_alone), *chosen]
