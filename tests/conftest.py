"""Fixtures of the whole suite: every temporary file a test or the code under test makes lands under pytest's own
temporary directory (``tmp_path_factory``), never loose in the system's temp directory."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True, scope="session")
def temp_under_pytest(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``tempfile``'s directory for this session (and ``$TMPDIR`` for the commands tests start): a folder of
    pytest's, removed with pytest's old runs. SB3 loggers that a test builds itself (``model.learn`` on a fresh
    model) put their ``SB3-<date>`` folders there too."""
    folder = str(tmp_path_factory.mktemp("tempdir"))
    saved_dir, saved_env = tempfile.tempdir, os.environ.get("TMPDIR")
    tempfile.tempdir, os.environ["TMPDIR"] = folder, folder
    yield folder
    tempfile.tempdir = saved_dir
    if saved_env is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = saved_env
