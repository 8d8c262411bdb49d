"""The package as pip builds it: one top-level name, ``bboxtune``, over the repository's source folders; every
package listed; the package data inside; one version everywhere it is written."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import yaml

import bboxtune

tomllib = pytest.importorskip("tomllib", reason="tomllib is Python >= 3.11")
REPO = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]


def test_every_source_package_is_listed_once() -> None:
    folders = {"bboxtune"}
    for name, folder in SETUPTOOLS["package-dir"].items():
        root = REPO / folder
        folders |= {".".join([name, *p.parent.relative_to(root).parts]) for p in root.rglob("__init__.py")}
    assert sorted(SETUPTOOLS["packages"]) == sorted(folders)
    assert SETUPTOOLS["package-dir"] == {"bboxtune": "bboxtune", "bboxtune.filters": "filters",
                                         "bboxtune.envs": "envs", "bboxtune.agents": "agents"}


def test_one_version_everywhere() -> None:
    version = PYPROJECT["project"]["version"]
    assert bboxtune.__version__ == version
    assert yaml.safe_load((REPO / "CITATION.cff").read_text(encoding="utf-8"))["version"] == version
    released = re.findall(r"^## \[(\d+\.\d+\.\d+)\]", (REPO / "CHANGELOG.md").read_text(encoding="utf-8"), re.M)
    assert released[0] == version


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Built from a copy of the sources (setuptools writes build/ and *.egg-info next to them)."""
    source, out = tmp_path_factory.mktemp("source"), tmp_path_factory.mktemp("wheel")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(REPO / name, source / name)
    for folder in ("bboxtune", *SETUPTOOLS["package-dir"].values()):
        if not (source / folder).exists():
            shutil.copytree(REPO / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out),
                    str(source)], check=True, capture_output=True, timeout=300)
    (found,) = out.glob("bboxtune-*.whl")
    return found


def test_the_wheel_has_one_top_level_name(wheel: Path) -> None:
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names if ".dist-info/" not in n} == {"bboxtune"}
    dist_info = next(n for n in names if n.endswith(".dist-info/top_level.txt")) if any(
        n.endswith("top_level.txt") for n in names) else None
    if dist_info:
        assert zipfile.ZipFile(wheel).read(dist_info).decode().split() == ["bboxtune"]


def test_the_wheel_holds_every_module_and_the_package_data(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    for part, folder in (("filters", "filters"), ("envs", "envs"), ("agents", "agents")):
        for source in (REPO / folder).rglob("*.py"):
            assert f"bboxtune/{part}/{source.relative_to(REPO / folder).as_posix()}" in names
    for data in [*(REPO / "agents/hyperparams").glob("*.yml"), *(REPO / "agents/pretrained").glob("*/*")]:
        assert f"bboxtune/agents/{data.relative_to(REPO / 'agents').as_posix()}" in names
