"""Fixtures for the env tests: OTB-backed cases run only when OTB_ROOT is set (CI sets it)."""

from __future__ import annotations

import os

import pytest

OTB_ROOT = os.environ.get("OTB_ROOT")
needs_otb = pytest.mark.skipif(not OTB_ROOT, reason="OTB_ROOT is unset: OTB-backed env cases need the OTB data")
