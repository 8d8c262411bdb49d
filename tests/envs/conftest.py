"""Fixtures for the env tests: OTB-backed cases run only when OTB_ROOT is set, MOT15-backed ones only when MOT_ROOT
is set (CI sets both)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

OTB_ROOT = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB_ROOT, reason="OTB_ROOT is unset: OTB-backed env cases need the OTB data")

MOT_ROOT = os.environ.get("MOT_ROOT")


@pytest.fixture(scope="session")
def mot_root() -> Path:
    """The MOT15 copy ``$MOT_ROOT``; the test is skipped when MOT_ROOT is unset."""
    if not MOT_ROOT:
        pytest.skip(reason="MOT_ROOT is unset: MOT15-backed cases need the MOT15 data (CI: MOT_ROOT=../shared/data/mot15)")
    return Path(MOT_ROOT)
