"""One bounded reader for every file a user can hand the project (annotations, configs, run files, JSON).

:func:`read_bytes` opens only a regular file (a directory, pipe or device is a ValueError naming the path,
so nothing blocks on a FIFO) and reads at most ``limit`` bytes (a larger file is a ValueError naming the
limit), so the time and memory of every reader built on it are bounded by the limit. :func:`read_text`
decodes UTF-8 (a byte-order mark is dropped; a bad byte is a ValueError naming the file and its line).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

MAX_TEXT_BYTES = 64 * 2**20  # text inputs: OTB100.json is 3.2 MB, config.yml / JSON run files a few kB


def check_regular(path: str | os.PathLike) -> None:
    """ValueError naming ``path`` unless it is an existing regular file (so opening it cannot block)."""
    try:
        mode = os.stat(path).st_mode
    except OSError as err:
        raise ValueError(f"{path}: cannot read the file ({err.strerror or err})") from None
    if stat.S_ISDIR(mode):
        raise ValueError(f"{path}: is a directory, expected a file")
    if not stat.S_ISREG(mode):
        raise ValueError(f"{path}: not a regular file (a pipe or device?), expected a file")


def read_bytes(path: str | os.PathLike, limit: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of the regular file ``path`` (at most ``limit``); ValueError naming the path otherwise."""
    check_regular(path)
    try:
        with open(path, "rb") as file:
            data = file.read(limit + 1)
    except OSError as err:
        raise ValueError(f"{path}: cannot read the file ({err.strerror or err})") from None
    if len(data) > limit:
        raise ValueError(f"{path}: file is larger than {limit} bytes (the reader's limit)")
    return data


def read_text(path: str | os.PathLike, limit: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of the regular file ``path`` (at most ``limit`` bytes, BOM dropped, line ends kept)."""
    data = read_bytes(path, limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}:{line}: not UTF-8 text (byte 0x{data[err.start]:02x} at offset {err.start})"
        ) from None


def data_root(root: str | os.PathLike | None, env_var: str, name: str) -> Path:
    """A data set's folder: ``root`` if given, else ``$env_var``; ValueError when neither names an existing path
    (``name``: the data set, e.g. "OTB", as the flag ``--<name>-root`` and the message say it)."""
    if root is None:
        root = os.environ.get(env_var) or None
        if root is None:
            raise ValueError(f"no {name} data location: pass {name.lower()}_root=DIR (--{name.lower()}-root DIR on the "
                             f"command line) or set {env_var}")
    path = Path(root)
    if not path.exists():
        raise ValueError(f"{name.lower()}_root / ${env_var}: {name} root {str(path)!r} does not exist")
    return path
