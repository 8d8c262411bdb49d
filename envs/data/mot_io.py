"""Strict readers for MOT Challenge 2015 text files: public detections, ground truth, tracker results, and the
``sequences.csv`` table of this project's MOT15 copy (``shared/data/mot15``).

Layout (MOT15, the only one accepted): every line holds exactly 10 comma-separated numbers

* detections ``<seq>/det/det.txt``: ``frame, -1, x, y, w, h, score, X, Y, Z``;
* ground truth ``<seq>/gt/gt.txt``: ``frame, id, x, y, w, h, flag, X, Y, Z``; flag 1 = the box counts, 0 = a
  row the benchmark ignores (kept here, marked ``flag = False``);
* tracker results: ``frame, id, x, y, w, h, score, X, Y, Z`` (trackers write -1 for X, Y, Z).

MOT16 and later ground truth (9 columns with class and visibility) is rejected by the column count. Frames are
1-based; boxes are **xywh** in pixels: (x, y) the top-left corner, (w, h) the size, with continuous areas as in
:mod:`bboxtune.envs.data.boxes` (``xywh_to_cxcywh`` gives the filters' (cx, cy, w, h)). The world coordinates X, Y, Z
(ETH sequences) are checked as numbers and not returned. Row i of every returned array is line i + 1.

The reader follows :mod:`bboxtune.envs.data.otb_io`: ``ValueError("<file>:<line>: <what is wrong; allowed ...>")`` on
malformed input, never a silent wrong or dropped value, in time linear in the file size (no regex; a
vectorised path for the whole file, else for each block of 1,000 lines, and the line-by-line checker, which
names the first bad line, for a block it does not take). Limits: files up to :data:`MAX_FILE_BYTES` (64 MiB),
lines up to :data:`MAX_LINE_CHARS` (1,024) characters, numbers as in :mod:`bboxtune.envs.data.number_grammar`. Accepted:

* UTF-8 (a byte-order mark is allowed), LF or CRLF line ends, blank lines only at the end of the file (the
  ETH-Pedcross2 det.txt ends with one); commas between fields, optionally with spaces or tabs around them;
* frame: an integer value (``3`` or ``3.0``) with 1 <= frame <= :data:`MAX_INDEX`; id: an integer value with
  \\|id\\| <= :data:`MAX_INDEX` (detections: exactly -1); w, h > 0 (no zero-size boxes); \\|x\\|, \\|y\\|, w, h
  <= 1e7 px (:data:`bboxtune.envs.data.boxes.MAX_COORD`); flag 0 or 1; every number finite. A (frame, id) pair
  repeated in ground truth or results is an error naming both lines.
* An empty (or blank) detection or results file has no rows; an empty ground-truth file is an error.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bboxtune.envs.data import textfile
from bboxtune.envs.data.boxes import COORD_RULE, beyond_max_coord
from bboxtune.envs.data.number_grammar import comma_values, parse_float, shorten
from bboxtune.envs.data.otb_io import csv_int, read_csv_table, read_text

MAX_FILE_BYTES = textfile.MAX_TEXT_BYTES  # read_text's limit; the largest MOT15 gt.txt is 0.3 MB
MAX_LINE_CHARS = 1024  # a MOT line of ten full-precision doubles takes about 250
MAX_INDEX = 10**9  # largest frame number and |id|: exact in a float, and frame spans stay allocatable
N_COLUMNS = 10
_NUMBER_BYTES = b"0123456789+-.eE"
_SEPARATORS = b"," * (N_COLUMNS - 1)
_BLOCK_LINES = 1000  # lines per block of the fallback: one bad line costs the exact check of one block
_LAYOUT = {"det": "frame,-1,x,y,w,h,score,X,Y,Z", "gt": "frame,id,x,y,w,h,flag,X,Y,Z",
           "results": "frame,id,x,y,w,h,score,X,Y,Z"}


@dataclass(frozen=True, eq=False)
class Detections:
    """Public detections of one sequence (rows in file order)."""

    frame: np.ndarray  # (N,) int64, 1-based
    box: np.ndarray  # (N, 4) float xywh px
    score: np.ndarray  # (N,) float, the detector's confidence (may be negative)

    def __len__(self) -> int:
        return len(self.frame)


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Ground truth of one sequence (rows in file order, flag-0 rows included)."""

    frame: np.ndarray  # (N,) int64, 1-based
    id: np.ndarray  # (N,) int64 identity
    box: np.ndarray  # (N, 4) float xywh px
    flag: np.ndarray  # (N,) bool: True = the box counts, False = a row to ignore (flag 0)

    def __len__(self) -> int:
        return len(self.frame)


@dataclass(frozen=True, eq=False)
class Results:
    """A tracker's results on one sequence (rows in file order)."""

    frame: np.ndarray  # (N,) int64, 1-based
    id: np.ndarray  # (N,) int64 track id
    box: np.ndarray  # (N, 4) float xywh px
    score: np.ndarray  # (N,) float confidence

    def __len__(self) -> int:
        return len(self.frame)


@dataclass(frozen=True)
class SequenceInfo:
    """One row of ``sequences.csv``; the counts are None where the table lacks their column."""

    name: str
    fps: int  # frames per second: tau = 1 / fps
    frames: int  # the last frame number of the sequence
    identities: int | None = None
    gt_rows: int | None = None
    gt_rows_flag0: int | None = None
    detections: int | None = None


# --- the 10-column text ---------------------------------------------------------------------------------------
def _fast_rows(body: str) -> np.ndarray | None:
    """(N, 10) values of lines (``body``, no final newline) that are each ten numbers joined by single commas,
    in vectorised linear time; None for any other text (then the line-by-line checker decides)."""
    if not body.isascii():
        return None
    n_lines = body.count("\n") + 1
    if body.encode("ascii").translate(None, _NUMBER_BYTES) != (_SEPARATORS + b"\n") * (n_lines - 1) + _SEPARATORS:
        return None
    return comma_values(body, N_COLUMNS)


def _parse_line(line: str, where: str, layout: str) -> list[float]:
    if len(line) > MAX_LINE_CHARS:
        raise ValueError(f"{where}: line is {len(line)} characters long; allowed at most {MAX_LINE_CHARS}")
    if not line.strip(" \t"):
        raise ValueError(f"{where}: blank line inside the file; allowed blank lines only at the end")
    fields = [f.strip(" \t") for f in line.split(",")]
    if len(fields) != N_COLUMNS:
        raise ValueError(f"{where}: expected {N_COLUMNS} comma-separated values {layout}, got {len(fields)}: "
                         f"{shorten(line.strip())}")
    try:
        return [parse_float(f) for f in fields]
    except ValueError as err:
        raise ValueError(f"{where}: {err} (line {shorten(line.strip())})") from None


def _rows(text: str, source: str, layout: str) -> np.ndarray:
    """(N, 10) values of ``text``: the vectorised path for the whole text, else per block of lines."""
    if not text.strip(" \t\n"):
        return np.empty((0, N_COLUMNS))
    values = _fast_rows(text.rstrip("\n"))
    if values is not None:
        return values
    lines = text.rstrip(" \t\n").split("\n")
    blocks = []
    for start in range(0, len(lines), _BLOCK_LINES):
        block = lines[start:start + _BLOCK_LINES]
        values = _fast_rows("\n".join(block))
        if values is None:
            values = np.array([_parse_line(line, f"{source}:{i}", layout)
                               for i, line in enumerate(block, start=start + 1)])
        blocks.append(values)
    return np.concatenate(blocks)


def _number(value: float) -> str:
    return str(int(value)) if value.is_integer() and abs(value) < 1e18 else repr(float(value))


def _first_error(source: str, checks: list[tuple[np.ndarray, Callable[[int], str]]]) -> None:
    """Raise for the earliest row any check flags: ``checks`` are (bad-row mask, message of row i)."""
    firsts = [(int(np.argmax(bad)), message) for bad, message in checks if bad.any()]
    if firsts:
        i, message = min(firsts, key=lambda item: item[0])
        raise ValueError(f"{source}:{i + 1}: {message(i)}")


def _check_unique(frame: np.ndarray, ident: np.ndarray, source: str) -> None:
    """ValueError naming both lines of the repeated (frame, id) pair whose second line comes first."""
    order = np.lexsort((np.arange(len(frame)), ident, frame))
    same = (np.diff(frame[order]) == 0) & (np.diff(ident[order]) == 0)
    if same.any():
        later = order[1:][same]
        j = int(np.argmin(later))
        first = order[np.flatnonzero(same)[j]]  # the earliest second occurrence follows its key's first line
        raise ValueError(f"{source}:{later[j] + 1}: repeats frame {frame[later[j]]}, id {ident[later[j]]} of "
                         f"line {first + 1}; allowed one row per (frame, id)")


def _parse(text: str, source: str, kind: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Checked (frame, id, values) of a 10-column file of ``kind`` ("det", "gt" or "results")."""
    values = _rows(text, source, _LAYOUT[kind])
    if kind == "gt" and not len(values):
        raise ValueError(f"{source}:1: empty ground-truth file; allowed lines {_LAYOUT[kind]}")
    frame, ident, w, h, col7 = values[:, 0], values[:, 1], values[:, 4], values[:, 5], values[:, 6]
    checks: list[tuple[np.ndarray, Callable[[int], str]]] = [
        (~((frame == np.round(frame)) & (frame >= 1) & (frame <= MAX_INDEX)),
         lambda i: f"frame {_number(frame[i])}; allowed integers 1 <= frame <= {MAX_INDEX}"),
        (~((w > 0) & (h > 0)), lambda i: f"box size w={_number(w[i])}, h={_number(h[i])}; allowed w, h > 0"),
        (beyond_max_coord(values[:, 2:6]), lambda i: f"box {values[i, 2:6].tolist()} is too large; allowed {COORD_RULE}"),
    ]
    if kind == "det":
        checks.append((ident != -1, lambda i: f"id {_number(ident[i])}; allowed -1 (detections have no identity)"))
    else:
        checks.append((~((ident == np.round(ident)) & (np.abs(ident) <= MAX_INDEX)),
                       lambda i: f"id {_number(ident[i])}; allowed integers with |id| <= {MAX_INDEX}"))
    if kind == "gt":
        checks.append(((col7 != 0) & (col7 != 1), lambda i: f"flag {_number(col7[i])}; allowed 0 or 1"))
    _first_error(source, checks)
    frames, ids = frame.astype(np.int64), ident.astype(np.int64)
    if kind != "det":
        _check_unique(frames, ids, source)
    return frames, ids, values


def read_detections(path: str | os.PathLike) -> Detections:
    """Public detections ``frame, -1, x, y, w, h, score, X, Y, Z`` (see the module docstring)."""
    frame, _, values = _parse(read_text(path), str(path), "det")
    return Detections(frame=frame, box=values[:, 2:6].copy(), score=values[:, 6].copy())


def read_ground_truth(path: str | os.PathLike) -> GroundTruth:
    """Ground truth ``frame, id, x, y, w, h, flag, X, Y, Z``; flag-0 rows are kept with ``flag = False``."""
    frame, ident, values = _parse(read_text(path), str(path), "gt")
    return GroundTruth(frame=frame, id=ident, box=values[:, 2:6].copy(), flag=values[:, 6] == 1)


def read_results(path: str | os.PathLike) -> Results:
    """Tracker results ``frame, id, x, y, w, h, score, X, Y, Z`` (one row per frame and track id)."""
    frame, ident, values = _parse(read_text(path), str(path), "results")
    return Results(frame=frame, id=ident, box=values[:, 2:6].copy(), score=values[:, 6].copy())


# --- sequences.csv ---------------------------------------------------------------------------------------------
def read_sequences_csv(root: str | os.PathLike) -> dict[str, SequenceInfo]:
    """Rows of ``<root>/sequences.csv`` by sequence name, in file order.

    Required columns: sequence, fps, frames (integers >= 1); optional: identities, gt_rows, gt_rows_flag0,
    detections (integers >= 0). A repeated sequence, an empty or non-integer cell is a ValueError naming the line."""
    path = Path(root) / "sequences.csv"
    out: dict[str, SequenceInfo] = {}
    first_line: dict[str, int] = {}
    for line, row in read_csv_table(path, ("sequence", "fps", "frames")):
        name = row["sequence"]
        if name in out:
            raise ValueError(f"{path}:{line}: duplicate row for sequence {name!r} (first at line {first_line[name]})")
        counts = {c: csv_int(row, c, path, line) for c in ("identities", "gt_rows", "gt_rows_flag0", "detections")
                  if c in row}
        first_line[name] = line
        out[name] = SequenceInfo(name=name, fps=csv_int(row, "fps", path, line, low=1),
                                 frames=csv_int(row, "frames", path, line, low=1), **counts)
    return out
