"""bboxtune.envs.data.atomic_files: the new file appears whole or not at all, the previous one survives a failing writer, no
temporary file is left behind, and the temporary name keeps the destination's suffix."""

from __future__ import annotations

import stat
from pathlib import Path

import numpy as np
import pytest

from bboxtune.envs.data import atomic_files
from bboxtune.envs.data.atomic_files import atomic_write, atomic_write_file, write_text_atomic


class WriterFailed(Exception):
    pass


def test_text_written_and_nothing_else_left(tmp_path):
    target = tmp_path / "a.txt"
    write_text_atomic(target, "first\n")
    write_text_atomic(target, "second ψ\n")  # replaces; UTF-8
    assert target.read_bytes() == "second ψ\n".encode()
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_file_handle_writer(tmp_path):
    target = tmp_path / "a.bin"
    atomic_write_file(target, lambda fh: fh.write(b"\x00\x01"))
    assert target.read_bytes() == b"\x00\x01"


@pytest.mark.parametrize("writer", ["path", "handle"])
def test_failure_keeps_the_previous_file_and_removes_the_temporary(tmp_path, writer):
    target = tmp_path / "a.txt"
    target.write_text("old")

    def by_path(tmp: Path) -> None:
        tmp.write_text("half")
        raise WriterFailed

    def by_handle(fh) -> None:
        fh.write(b"half")
        raise WriterFailed

    with pytest.raises(WriterFailed):
        if writer == "path":
            atomic_write(target, by_path)
        else:
            atomic_write_file(target, by_handle)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_failure_without_a_previous_file_leaves_nothing(tmp_path):
    with pytest.raises(KeyboardInterrupt):  # not only Exception: an interrupted writer cleans up too
        atomic_write(tmp_path / "a.txt", lambda tmp: (_ for _ in ()).throw(KeyboardInterrupt))
    assert list(tmp_path.iterdir()) == []


def test_temporary_file_keeps_the_suffix_and_folder(tmp_path):
    seen: list[Path] = []

    def write(tmp: Path) -> None:
        seen.append(tmp)
        np.savez(tmp, x=np.arange(3))  # numpy.savez appends .npz to a name without it

    target = tmp_path / "cache.npz"
    atomic_write(target, write)
    (tmp,) = seen
    assert tmp.parent == tmp_path and tmp.suffix == ".npz" and tmp.name.startswith(".cache.")
    with np.load(target) as data:
        assert data["x"].tolist() == [0, 1, 2]
    assert [p.name for p in tmp_path.iterdir()] == ["cache.npz"]


def test_permissions_follow_the_umask_not_mkstemp(tmp_path, monkeypatch):
    monkeypatch.setattr(atomic_files, "_UMASK", 0o027)  # the process umask, as read at import
    write_text_atomic(tmp_path / "a.txt", "x")
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o640  # mkstemp alone would give 0o600
