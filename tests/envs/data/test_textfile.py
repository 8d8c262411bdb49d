"""The one bounded reader (bboxtune.envs.data.textfile) and the readers built on it: never block on a pipe, never read
past the limit, name the file."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from bboxtune.agents import readers
from bboxtune.agents.training.checkpoints import _pointer
from bboxtune.agents.training.run_files import RunError, read_json
from bboxtune.envs.data import textfile


@pytest.fixture
def fifo(tmp_path: Path) -> Path:
    path = tmp_path / "pipe"
    os.mkfifo(path)  # opening it for reading would block until a writer appears
    return path


@pytest.mark.parametrize("reader", [textfile.read_bytes, textfile.read_text])
def test_pipe_directory_and_missing_file_are_named_errors(reader, fifo: Path, tmp_path: Path):
    for path, why in ((fifo, "not a regular file"), (tmp_path, "is a directory"), (tmp_path / "no", "cannot read")):
        with pytest.raises(ValueError, match=why) as err:
            reader(path)
        assert str(path) in str(err.value)


def test_limit_and_utf8_line(tmp_path: Path):
    path = tmp_path / "f.txt"
    path.write_bytes(b"\xef\xbb\xbfab\ncd\n")
    assert textfile.read_text(path) == "ab\ncd\n"
    assert textfile.read_bytes(path, limit=9) == path.read_bytes()
    with pytest.raises(ValueError, match="larger than 8 bytes"):
        textfile.read_bytes(path, limit=8)
    path.write_bytes(b"ok\nok\n\xff\n")
    with pytest.raises(ValueError, match=r"f\.txt:3: not UTF-8"):
        textfile.read_text(path)


def test_run_file_readers_refuse_a_pipe(fifo: Path, tmp_path: Path):
    with pytest.raises(ValueError, match="not a regular file"):
        readers.read_json(fifo)
    with pytest.raises(ValueError, match="not a regular file"):
        readers.read_yaml(fifo)
    with pytest.raises(RunError, match="not a regular file"):
        read_json(fifo)
    os.mkfifo(tmp_path / "latest")
    logged: list[str] = []
    assert _pointer(tmp_path, logged.append) is None
    assert "not a regular file" in logged[0]


def test_replay_buffer_reader_refuses_a_pipe(fifo: Path):
    from bboxtune.agents.training.run_files import load_replay_buffer

    class Model:  # only the buffer's attributes are read before the file is opened
        replay_buffer = type("Buffer", (), {"observations": 0})()

    with pytest.raises(RunError, match="not a regular file"):
        load_replay_buffer(Model(), fifo)
