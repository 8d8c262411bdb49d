"""Strict readers for OTB annotation files: box text files, the pysot ``OTB100.json`` and the CSV tables.

Every reader fails with ``ValueError("<file>:<line>: <what is wrong>")`` on malformed input, never with a
silent wrong value. Accepted box text (one x, y, w, h box per line, OTB's 1-based pixel coordinates):

* separators: commas (optionally with spaces around them), tabs or spaces, one kind per line. Different lines
  may use different kinds (the original BlurCar1 file has one space-separated line among comma lines); a line
  that mixes commas with whitespace separators is an error;
* UTF-8 (a byte-order mark is allowed), LF or CRLF line ends, blank lines only at the end of the file;
* finite numbers (integers, decimals, exponents). NaN / inf, negative w or h, and any other column count are
  errors;
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
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_COMMA_FILE = re.compile(rf"(?:{_NUM},{_NUM},{_NUM},{_NUM}\n)*{_NUM},{_NUM},{_NUM},{_NUM}\n*")  # fast path


def read_text(path: str | os.PathLike) -> str:
    """File contents as text; a non-UTF-8 byte is a ValueError naming the file and line."""
    data = Path(path).read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}:{line}: not UTF-8 text (byte 0x{data[err.start]:02x} at offset {err.start})"
        ) from None
    return text.replace("\r\n", "\n").replace("\r", "\n")


def _parse_line(line: str, where: str) -> list[float]:
    if "," in line:
        fields = [f.strip() for f in line.split(",")]
        if any(re.search(r"\s", f) for f in fields):
            raise ValueError(f"{where}: mixes comma and whitespace separators in one line: {line.strip()!r}")
    else:
        fields = line.split()
    if len(fields) != 4:
        raise ValueError(f"{where}: expected 4 values x,y,w,h, got {len(fields)}: {line.strip()!r}")
    values = []
    for f in fields:
        try:
            values.append(float(f))
        except ValueError:
            raise ValueError(f"{where}: {f!r} is not a number (line {line.strip()!r})") from None
    return values


def check_boxes(boxes: np.ndarray, locate: Callable[[int], str]) -> np.ndarray:
    """Validate parsed (T, 4) boxes; ``locate(i)`` names row i in messages. Zero sizes become NaN rows."""
    finite = np.isfinite(boxes).all(axis=1)
    if not finite.all():
        i = int(np.argmin(finite))
        raise ValueError(
            f"{locate(i)}: non-finite value in {boxes[i].tolist()}; allowed finite numbers "
            "(write 0,0,0,0 for a missing frame)"
        )
    negative = (boxes[:, 2:] < 0).any(axis=1)
    if negative.any():
        i = int(np.argmax(negative))
        raise ValueError(f"{locate(i)}: negative size w={boxes[i, 2]:g}, h={boxes[i, 3]:g}; allowed w, h >= 0")
    empty = (boxes[:, 2:] == 0).any(axis=1)
    for i in np.flatnonzero(empty):
        logger.info("%s: zero-size box %s read as a missing frame", locate(int(i)), boxes[i].tolist())
    out = boxes.astype(float, copy=True)
    out[empty] = np.nan
    return out


def parse_boxes(text: str, source: str) -> np.ndarray:
    """Parse box text (see the module docstring) into (T, 4) xywh; ``source`` names the file in errors."""
    if not text.strip():
        raise ValueError(f"{source}:1: empty annotation file (no boxes)")
    if _COMMA_FILE.fullmatch(text):
        values = np.array(re.split(r"[,\n]", text.rstrip("\n")), dtype=float).reshape(-1, 4)
        return check_boxes(values, lambda i: f"{source}:{i + 1}")
    lines = text.rstrip().split("\n")
    rows = []
    for i, line in enumerate(lines):
        if not line.strip():
            raise ValueError(f"{source}:{i + 1}: blank line inside the file; every line must hold one box")
        rows.append(_parse_line(line, f"{source}:{i + 1}"))
    return check_boxes(np.array(rows, dtype=float), lambda i: f"{source}:{i + 1}")


def read_boxes(path: str | os.PathLike, *, n_expected: int | None = None) -> np.ndarray:
    """Read a box text file into (T, 4) float xywh with NaN rows for missing (zero-size) frames.

    ``n_expected`` (e.g. ``n_frames`` from ``sequences.csv``): any other line count is a ValueError."""
    boxes = parse_boxes(read_text(path), str(path))
    if n_expected is not None and len(boxes) != n_expected:
        line = min(len(boxes), n_expected) + 1
        raise ValueError(f"{path}:{line}: file has {len(boxes)} boxes, expected {n_expected}")
    return boxes


def read_csv_table(path: str | os.PathLike, required: tuple[str, ...]) -> list[dict[str, str]]:
    """Rows of a CSV file with a header containing ``required``; errors name the file and line."""
    reader = csv.DictReader(io.StringIO(read_text(path)))
    missing = [c for c in required if c not in (reader.fieldnames or [])]
    if missing:
        raise ValueError(f"{path}:1: header {reader.fieldnames} lacks column(s) {missing}")
    rows = []
    for row in reader:
        if None in row or any(row[c] is None or row[c] == "" for c in required):
            raise ValueError(f"{path}:{reader.line_num}: wrong number of fields or empty value in {row}")
        rows.append(row)
    return rows


def csv_int(row: dict[str, str], column: str, path: str | os.PathLike, line: int, low: int = 0) -> int:
    """An integer cell >= ``low``, or a ValueError naming the file, line and column."""
    try:
        value = int(row[column])
    except ValueError:
        raise ValueError(f"{path}:{line}: {column}={row[column]!r} is not an integer") from None
    if value < low:
        raise ValueError(f"{path}:{line}: {column}={value} is out of range: allowed >= {low}")
    return value


def read_pysot_json(path: str | os.PathLike) -> dict[str, dict]:
    """Load a pysot-format ``OTB100.json``: {video: {video_dir, init_rect, img_names, gt_rect, attr}}.

    Returns {name: {"gt": (T, 4) xywh, "first_frame": int, "video": str, "attributes": frozenset}}; the
    first frame is the number in the first image name (``BlurCar1/img/0247.jpg`` → 247) and the video its
    first folder (``Jogging/img/0001.jpg`` → Jogging; without a folder, the name less a ``-<n>`` suffix)."""
    try:
        raw = json.loads(read_text(path))
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}:{err.lineno}: invalid JSON ({err.msg})") from None
    if not isinstance(raw, dict) or not raw:
        raise ValueError(f"{path}:1: expected a non-empty object {{video: {{...}}}}")
    out = {}
    for name, entry in raw.items():
        where = f"{path}: video {name!r}"
        if not isinstance(entry, dict) or not {"gt_rect", "img_names"} <= set(entry):
            raise ValueError(f"{where}: needs keys 'gt_rect' and 'img_names'")
        rects, imgs = entry["gt_rect"], entry["img_names"]
        if not isinstance(rects, list) or not rects or len(rects) != len(imgs):
            raise ValueError(f"{where}: gt_rect has {_len(rects)} boxes for {_len(imgs)} img_names")
        for i, r in enumerate(rects):
            if not isinstance(r, list) or len(r) != 4 or not all(_is_number(v) for v in r):
                raise ValueError(f"{where} gt_rect[{i}]: expected 4 numbers x,y,w,h, got {r!r}")
        digits = re.findall(r"\d+", os.path.basename(str(imgs[0])))
        if not digits:
            raise ValueError(f"{where} img_names[0]={imgs[0]!r}: no frame number in the file name")
        gt = check_boxes(np.array(rects, dtype=float), lambda i, w=where: f"{w} gt_rect[{i}]")
        out[name] = {
            "gt": gt,
            "first_frame": int(digits[-1]),
            "video": str(imgs[0]).split("/")[0] if "/" in str(imgs[0]) else re.sub(r"-\d+$", "", name),
            "attributes": frozenset(entry.get("attr", [])),
        }
    return out


def _len(value: object) -> str:
    return str(len(value)) if isinstance(value, list) else repr(value)


def _is_number(value: object) -> bool:
    """int or float (NaN included: check_boxes reports it), not bool."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)
