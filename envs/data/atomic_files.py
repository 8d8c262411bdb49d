"""Atomic file writes: a killed or failing writer leaves either the previous file or the complete new one.

Every writer here writes a temporary file in the destination's folder (so the final ``os.replace`` is a
rename within one file system) and then replaces the destination with it. The temporary file is named
``.<stem>.<random>.tmp<suffix>``: hidden, unique (``tempfile.mkstemp``) and with the destination's suffix,
because some writers add a suffix to names without it (SB3's ``save`` appends ``.zip``, ``numpy.savez``
``.npz``). It is removed if the writer fails (any exception, KeyboardInterrupt included). The new file gets
the permissions a plain ``open`` would give it (0666 less the process umask, read once at import), not
``mkstemp``'s 0600. The destination's folder must exist.

It lives in the lowest layer that writes files (``bboxtune.envs.data``) and imports nothing from ``envs`` or ``agents``.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO

_UMASK = os.umask(0o022)  # read the process umask (os.umask returns the old value) ...
os.umask(_UMASK)  # ... and put it back


def atomic_write(path: Path | str, write: Callable[[Path], object]) -> None:
    """Write ``path`` by calling ``write(tmp)`` with the path of a temporary file beside it (same folder and
    suffix; it exists, empty), then ``os.replace`` it onto ``path``. ``write``'s return value is ignored."""
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    tmp = Path(name)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_file(path: Path | str, write: Callable[[IO[bytes]], object]) -> None:
    """Write ``path`` by calling ``write(fh)`` with a binary file open for writing (a temporary file beside
    ``path``), then ``os.replace`` it onto ``path``."""

    def through_handle(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            write(fh)

    atomic_write(path, through_handle)


def write_text_atomic(path: Path | str, text: str) -> None:
    """``text`` into ``path`` (UTF-8), atomically."""
    atomic_write_file(path, lambda fh: fh.write(text.encode("utf-8")))
