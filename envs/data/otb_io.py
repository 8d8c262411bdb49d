"""Strict readers for OTB annotation files: box text files, the pysot ``OTB100.json`` and the CSV tables.

Every reader fails with ``ValueError("<file>:<line>: <what is wrong>")`` on malformed input, never with a
silent wrong value, and runs in time linear in the file size: no backtracking regex over the text; box files
take a vectorised path for the whole file, else for each block of 1,000 lines, and a block it does not take
goes to the line-by-line checker, which names the first bad line. Limits: files up to
:data:`MAX_FILE_BYTES` (64 MiB), box lines up to :data:`MAX_LINE_CHARS` (1,024) characters, numbers as in
:mod:`bboxtune.envs.data.number_grammar` (ASCII decimals of at most 64 characters; no ``_``, nan/inf, hex or non-ASCII
digits). A path that is a directory, pipe or device is an error naming it. Accepted box text (one x, y, w, h
box per line, OTB's 1-based pixel coordinates):

* separators: commas (optionally with spaces or tabs around them), tabs or spaces, one kind per line.
  Different lines may use different kinds (the original BlurCar1 file has one space-separated line among comma
  lines); a line that mixes commas with whitespace separators is an error;
* UTF-8 (a byte-order mark is allowed), LF or CRLF line ends, blank lines only at the end of the file;
* finite numbers in the grammar above, at most 1e7 px in absolute value (:data:`bboxtune.envs.data.boxes.MAX_COORD`).
  Negative w or h and any other column count are errors;
* **a box with w = 0 or h = 0 is a missing frame**: it becomes a NaN row, and an INFO log names the file and
  line (OTB marks the last frames of Board and Twinnings with ``0,0,0,0``). x and y may be negative (part of
  the box outside the image, e.g. Biker).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import os
import re
from collections.abc import Callable

import numpy as np

from bboxtune.envs.data import textfile
from bboxtune.envs.data.boxes import COORD_RULE, beyond_max_coord
from bboxtune.envs.data.number_grammar import MAX_NUMBER_CHARS, comma_values, parse_float, parse_int, shorten

logger = logging.getLogger(__name__)

MAX_FILE_BYTES = textfile.MAX_TEXT_BYTES  # OTB100.json is 3.2 MB, the longest OTB box file 90 kB
MAX_LINE_CHARS = 1024  # a box line of four full-precision doubles takes about 100
_NUMBER_BYTES = b"0123456789+-.eE"
_BLOCK_LINES = 1000  # lines per block of the fallback: one bad line costs the exact check of one block


def read_text(path: str | os.PathLike) -> str:
    """Contents of a regular file of at most :data:`MAX_FILE_BYTES` as text with ``\\n`` line ends.

    A missing or unreadable path, a directory, pipe or device, a larger file, or a non-UTF-8 byte is a
    ValueError naming the file (and the line of the bad byte). A UTF-8 byte-order mark is dropped."""
    return textfile.read_text(path, MAX_FILE_BYTES).replace("\r\n", "\n").replace("\r", "\n")


def video_of(name: str) -> str:
    """The video a target belongs to: ``"Jogging-2"`` → ``"Jogging"``, ``"Car4"`` → ``"Car4"``."""
    head, dash, tail = name.rpartition("-")
    return head if dash and tail.isascii() and tail.isdigit() else name


# --- box text --------------------------------------------------------------------------------------------------
def _fields(line: str, where: str) -> list[str]:
    if "," not in line:
        return [f for f in line.replace("\t", " ").split(" ") if f]
    fields = [f.strip(" \t") for f in line.split(",")]
    if any(" " in f or "\t" in f for f in fields):
        raise ValueError(f"{where}: mixes comma and whitespace separators in one line: {shorten(line.strip())}")
    return fields


def _parse_line(line: str, where: str) -> list[float]:
    if len(line) > MAX_LINE_CHARS:
        raise ValueError(f"{where}: line is {len(line)} characters long; allowed at most {MAX_LINE_CHARS}")
    if not line.strip(" \t"):
        raise ValueError(f"{where}: blank line inside the file; every line must hold one box")
    fields = _fields(line, where)
    if len(fields) != 4:
        raise ValueError(f"{where}: expected 4 values x,y,w,h, got {len(fields)}: {shorten(line.strip())}")
    try:
        return [parse_float(f) for f in fields]
    except ValueError as err:
        raise ValueError(f"{where}: {err} (line {shorten(line.strip())})") from None


def _fast_boxes(body: str) -> np.ndarray | None:
    """(T, 4) values of lines (``body``, no final newline) that are each four numbers joined by single commas (or
    by single tabs, when no line has a comma), in vectorised linear time; None for any other text (then the
    line-by-line checker decides). Characters limited to digits, sign, point and e/E make ``float`` parse
    exactly the grammar of :mod:`bboxtune.envs.data.number_grammar`."""
    if not body.isascii():
        return None
    if "," not in body:
        body = body.replace("\t", ",")
    n_lines = body.count("\n") + 1
    if body.encode("ascii").translate(None, _NUMBER_BYTES) != b",,,\n" * (n_lines - 1) + b",,,":
        return None
    return comma_values(body, 4)


def check_boxes(boxes: np.ndarray, locate: Callable[[int], str]) -> np.ndarray:
    """Validate parsed (T, 4) boxes; ``locate(i)`` names row i in messages. Zero sizes become NaN rows."""
    finite = np.isfinite(boxes).all(axis=1)
    if not finite.all():
        i = int(np.argmin(finite))
        raise ValueError(
            f"{locate(i)}: non-finite value in {boxes[i].tolist()}; allowed finite numbers "
            "(write 0,0,0,0 for a missing frame)"
        )
    huge = beyond_max_coord(boxes)
    if huge.any():
        i = int(np.argmax(huge))
        raise ValueError(f"{locate(i)}: box {boxes[i].tolist()} is too large; allowed {COORD_RULE}")
    negative = (boxes[:, 2:] < 0).any(axis=1)
    if negative.any():
        i = int(np.argmax(negative))
        raise ValueError(f"{locate(i)}: negative size w={boxes[i, 2]:g}, h={boxes[i, 3]:g}; allowed w, h >= 0")
    empty = (boxes[:, 2:] == 0).any(axis=1)
    for k in np.flatnonzero(empty):
        logger.info("%s: zero-size box %s read as a missing frame", locate(int(k)), boxes[k].tolist())
    out = boxes.astype(float, copy=True)
    out[empty] = np.nan
    return out


def _checked_boxes(lines: list[str], source: str) -> np.ndarray:
    """(T, 4) values of ``lines``, checked in blocks of :data:`_BLOCK_LINES`: the vectorised path for a block,
    the line-by-line checker (which names the first bad line) for a block it does not take."""
    blocks = []
    for start in range(0, len(lines), _BLOCK_LINES):
        block = lines[start:start + _BLOCK_LINES]
        values = _fast_boxes("\n".join(block))
        if values is None:
            values = np.array([_parse_line(line, f"{source}:{i}") for i, line in enumerate(block, start=start + 1)])
        blocks.append(values)
    return np.concatenate(blocks)


def parse_boxes(text: str, source: str) -> np.ndarray:
    """Parse box text (see the module docstring) into (T, 4) xywh; ``source`` names the file in errors."""
    if not text.strip():
        raise ValueError(f"{source}:1: empty annotation file (no boxes)")
    values = _fast_boxes(text.rstrip("\n"))
    if values is None:
        values = _checked_boxes(text.rstrip(" \t\n").split("\n"), source)
    return check_boxes(values, lambda i: f"{source}:{i + 1}")


def read_boxes(path: str | os.PathLike, *, n_expected: int | None = None) -> np.ndarray:
    """Read a box text file into (T, 4) float xywh with NaN rows for missing (zero-size) frames.

    ``n_expected`` (e.g. ``n_frames`` from ``sequences.csv``): any other line count is a ValueError."""
    boxes = parse_boxes(read_text(path), str(path))
    if n_expected is not None and len(boxes) != n_expected:
        line = min(len(boxes), n_expected) + 1
        raise ValueError(f"{path}:{line}: file has {len(boxes)} boxes, expected {n_expected}")
    return boxes


# --- CSV tables ------------------------------------------------------------------------------------------------
def read_csv_table(path: str | os.PathLike, required: tuple[str, ...]) -> list[tuple[int, dict[str, str]]]:
    """(line, row) pairs of a CSV file whose header has distinct names including ``required``.

    Every row must have as many fields as the header and non-empty ``required`` values; blank lines are
    skipped. Errors name the file and line (fields are limited to the csv module's 131,072 characters)."""
    reader = csv.DictReader(io.StringIO(read_text(path)))
    rows = []
    try:
        header = reader.fieldnames or []
        if len(set(header)) != len(header):
            raise ValueError(f"{path}:1: header {header} repeats a column name")
        missing = [c for c in required if c not in header]
        if missing:
            raise ValueError(f"{path}:1: header {header} lacks column(s) {missing}")
        for row in reader:
            if None in row or None in row.values() or any(row[c] == "" for c in required):
                raise ValueError(f"{path}:{reader.line_num}: wrong number of fields or empty value in "
                                 f"{shorten(str(row), 200)}")
            rows.append((reader.line_num, row))
    except csv.Error as err:
        raise ValueError(f"{path}:{reader.reader.line_num}: malformed CSV ({err})") from None
    return rows


def csv_int(row: dict[str, str], column: str, path: str | os.PathLike, line: int, low: int = 0) -> int:
    """An integer cell >= ``low`` (grammar of :func:`bboxtune.envs.data.number_grammar.parse_int`), or a ValueError naming the
    file, line and column."""
    try:
        value = parse_int(row[column])
    except ValueError as err:
        raise ValueError(f"{path}:{line}: {column}={err}") from None
    if value < low:
        raise ValueError(f"{path}:{line}: {column}={value} is out of range: allowed >= {low}")
    return value


# --- pysot JSON ------------------------------------------------------------------------------------------------
def _unique_keys(pairs: list[tuple[str, object]]) -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {shorten(key)} in one object")
        out[key] = value
    return out


def _json_number(literal: str) -> float:
    if len(literal) > MAX_NUMBER_CHARS:
        raise ValueError(f"number {shorten(literal)} is longer than {MAX_NUMBER_CHARS} characters")
    return float(literal)  # JSON's number grammar is a subset of bboxtune.envs.data.number_grammar's


def _is_number(value: object) -> bool:
    """int or float (NaN included: check_boxes reports it), not bool."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _strings(value: object) -> bool:
    return isinstance(value, list) and all(isinstance(v, str) for v in value)


def _pysot_entry(name: str, entry: object, where: str) -> dict:
    if not isinstance(entry, dict) or not {"gt_rect", "img_names"} <= set(entry):
        raise ValueError(f"{where}: needs keys 'gt_rect' and 'img_names'")
    rects, imgs, attr = entry["gt_rect"], entry["img_names"], entry.get("attr", [])
    if not isinstance(rects, list) or not rects or not _strings(imgs) or len(rects) != len(imgs):
        raise ValueError(f"{where}: gt_rect has {_len(rects)} boxes for {_len(imgs)} img_names (lists of boxes "
                         "and of strings of equal length >= 1)")
    if not _strings(attr):
        raise ValueError(f"{where}: attr={shorten(str(attr))}; allowed a list of attribute names")
    for i, r in enumerate(rects):
        if not isinstance(r, list) or len(r) != 4 or not all(_is_number(v) for v in r):
            raise ValueError(f"{where} gt_rect[{i}]: expected 4 numbers x,y,w,h, got {shorten(str(r))}")
    digits = re.findall(r"[0-9]+", os.path.basename(imgs[0]))  # linear: no nested or adjacent quantifiers
    try:
        first = parse_int(digits[-1]) if digits else 0
    except ValueError as err:
        raise ValueError(f"{where} img_names[0]: {err}") from None
    if first < 1:
        raise ValueError(f"{where} img_names[0]={shorten(imgs[0])}: no frame number >= 1 in the file name")
    return {
        "gt": check_boxes(np.array(rects, dtype=float), lambda i: f"{where} gt_rect[{i}]"),
        "first_frame": first,
        "video": imgs[0].split("/")[0] if "/" in imgs[0] else video_of(name),
        "attributes": frozenset(attr),
    }


def read_pysot_json(path: str | os.PathLike) -> dict[str, dict]:
    """Load a pysot-format ``OTB100.json``: {video: {video_dir, init_rect, img_names, gt_rect, attr}}.

    Returns {name: {"gt": (T, 4) xywh, "first_frame": int, "video": str, "attributes": frozenset}}; the
    first frame is the number in the first image name (``BlurCar1/img/0247.jpg`` → 247) and the video its
    first folder (``Jogging/img/0001.jpg`` → Jogging; without a folder, the name less a ``-<n>`` suffix).
    A key repeated in one object, a number over 64 characters or nesting too deep is invalid JSON."""
    text = read_text(path)
    try:
        raw = json.loads(text, object_pairs_hook=_unique_keys, parse_float=_json_number, parse_int=_json_number)
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}:{err.lineno}: invalid JSON ({err.msg})") from None
    except (ValueError, RecursionError) as err:
        raise ValueError(f"{path}: invalid JSON ({err})") from None
    if not isinstance(raw, dict) or not raw:
        raise ValueError(f"{path}:1: expected a non-empty object {{video: {{...}}}}")
    return {name: _pysot_entry(name, entry, f"{path}: video {shorten(name)}") for name, entry in raw.items()}


def _len(value: object) -> str:
    return str(len(value)) if isinstance(value, list) else shorten(repr(value))
