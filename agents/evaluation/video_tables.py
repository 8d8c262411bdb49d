"""Output files of the video commands (:mod:`bboxtune.agents.commands.track_video`, ``video_table``, ``video_camera``)
and of ``smooth``: CSV / JSON text, atomic files and whole output folders.

Every output file is written atomically (:mod:`bboxtune.envs.data.atomic_files`: a temporary file in the destination folder
moved into place with ``os.replace``), so a killed run leaves either the previous file or the complete new one.
:func:`publish_folder` does the same for a whole output folder: the files are written into a temporary sibling
folder that is then renamed to the destination, which must be absent or empty (``rename`` refuses a non-empty
one, so of two runs racing for one folder exactly one publishes and nothing is overwritten).
"""

from __future__ import annotations

import csv
import errno
import io
import json
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from bboxtune.envs.data.atomic_files import write_text_atomic


def write_text(path: Path, text: str) -> None:
    """``text`` into ``path`` atomically (:mod:`bboxtune.envs.data.atomic_files`), creating its folder if needed."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, text)


def json_text(doc: Any) -> str:
    """Indented JSON of ``doc`` (numpy scalars as floats), newline-terminated."""
    return json.dumps(doc, indent=2, default=float) + "\n"


def csv_text(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """CSV of ``header`` and ``rows``; floats with 6 significant digits."""
    buf = io.StringIO()
    out = csv.writer(buf, lineterminator="\n")
    out.writerow(header)
    for row in rows:
        out.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in row])
    return buf.getvalue()


def write_json(path: Path, doc: Any) -> None:
    write_text(path, json_text(doc))


def write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    write_text(path, csv_text(header, rows))


def folder_in_use(out: Path) -> str | None:
    """Why ``out`` cannot take a new output folder (it is a file, or a folder with something in it), else None."""
    if out.is_dir():
        return f"{out} exists and is not empty" if any(out.iterdir()) else None
    return f"{out} exists and is not a folder" if os.path.lexists(out) else None


def write_content(path: Path, content: str | bytes) -> None:
    """``content`` into the file ``path``: text as UTF-8, bytes as they are."""
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")


def publish_folder(out: Path, files: Mapping[str, str | bytes]) -> None:
    """Write ``files`` (relative path → text, or bytes written as they are) into a temporary sibling of ``out``, then
    rename it to ``out``.

    ``out`` must be absent or an empty folder (ValueError naming it otherwise, with nothing written); its
    parent folders are created."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        for name, content in files.items():
            path = tmp / name
            path.parent.mkdir(parents=True, exist_ok=True)
            write_content(path, content)
        try:
            os.rename(tmp, out)  # atomic; replaces only an empty folder
        except OSError as err:
            if err.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR):
                raise ValueError(folder_in_use(out) or f"{out}: {err.strerror}") from None
            raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

