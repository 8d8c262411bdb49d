"""scripts/setup.sh's shell logic with a fake interpreter that logs its arguments: no install, no network."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SETUP = REPO / "scripts" / "setup.sh"
CPU_INDEX = "https://download.pytorch.org/whl/cpu"
PRIMARY = "-m pip install -q torch==2.13.0+cpu"
FALLBACK = f"-m pip install -q --index-url {CPU_INDEX} torch==2.13.0"
# logs "$*" (one line per call) and fails when it contains one of the words of $FAKE_FAIL
FAKE = ('#!/usr/bin/env bash\necho "$*" >> "$FAKE_LOG"\n'
        'for w in ${FAKE_FAIL:-}; do [[ "$*" == *"$w"* ]] && exit 1; done\nexit 0\n')


def _fake(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(FAKE)
    path.chmod(0o755)
    return path


def _layout(tmp_path: Path) -> dict[str, str]:
    """A copy of the script in tmp/repo/scripts with a fake .venv/bin/python beside it and a fake python3 first on
    PATH, so that even a script that ran its set-up when sourced would reach fakes only; returns the env to use."""
    script = tmp_path / "repo" / "scripts" / "setup.sh"
    script.parent.mkdir(parents=True)
    shutil.copy(SETUP, script)
    _fake(tmp_path / "repo" / ".venv" / "bin" / "python")
    path = _fake(tmp_path / "path" / "python3").parent
    return {"SETUP": str(script), "PATH": f"{path}:{os.environ['PATH']}", "FAKE_LOG": str(tmp_path / "calls.log")}


def _bash(script: str, tmp_path: Path, **env: str) -> tuple[subprocess.CompletedProcess, list[str]]:
    """Runs ``script`` in bash (``$SETUP``: the copy of the set-up script); returns the result and the fakes' calls."""
    layout = _layout(tmp_path)
    done = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=60,
                          env={**os.environ, **layout, **env})
    log = Path(layout["FAKE_LOG"])
    return done, log.read_text().splitlines() if log.exists() else []


def _install_torch(tmp_path: Path, fail: str) -> tuple[subprocess.CompletedProcess, list[str]]:
    fake = _fake(tmp_path / "bin" / "python")
    return _bash('source "$SETUP"; VENV_PYTHON="$FAKE"; install_torch', tmp_path, FAKE=str(fake), FAKE_FAIL=fail)


def test_configured_indexes_first_and_only_when_they_have_the_cpu_wheel(tmp_path: Path) -> None:
    done, calls = _install_torch(tmp_path, fail="")
    assert done.returncode == 0 and calls == [PRIMARY], done.stderr


def test_falls_back_to_the_pytorch_cpu_index(tmp_path: Path) -> None:
    done, calls = _install_torch(tmp_path, fail="torch==2.13.0+cpu")
    assert done.returncode == 0 and calls == [PRIMARY, FALLBACK], done.stderr
    assert f"PyTorch CPU wheel index {CPU_INDEX}" in done.stderr


def test_fails_when_both_fail(tmp_path: Path) -> None:
    done, calls = _install_torch(tmp_path, fail="torch==2.13.0")
    assert done.returncode != 0 and calls == [PRIMARY, FALLBACK]


def test_sourcing_runs_nothing(tmp_path: Path) -> None:
    done, calls = _bash('source "$SETUP"; type install_torch check_cpu_torch main >/dev/null', tmp_path)
    assert done.returncode == 0 and calls == [], done.stderr


def test_running_installs_torch_then_the_package_then_checks_the_build(tmp_path: Path) -> None:
    done, calls = _bash('bash "$SETUP"', tmp_path, FAKE_FAIL="torch==2.13.0+cpu")
    assert done.returncode == 0, done.stderr
    assert calls == [PRIMARY, FALLBACK, "-m pip install -q -e .[dev]", "-"]  # "-": the check reads stdin


@pytest.mark.parametrize("cuda, hip, ok", [(None, None, True), ("12.8", None, False), (None, "6.2", False)])
def test_check_fails_loudly_on_a_gpu_build(tmp_path: Path, cuda: str | None, hip: str | None, ok: bool) -> None:
    """``check_cpu_torch`` with the real interpreter and a stand-in torch package that reports the given build."""
    package = tmp_path / "stand_in" / "torch"
    package.mkdir(parents=True)
    package.joinpath("__init__.py").write_text(
        f"__version__ = '2.13.0+test'\nclass version:\n    cuda = {cuda!r}\n    hip = {hip!r}\n")
    done, _ = _bash('source "$SETUP"; VENV_PYTHON="$PY"; check_cpu_torch', tmp_path, PY=sys.executable,
                    PYTHONPATH=str(package.parent))
    if ok:
        assert done.returncode == 0 and "torch 2.13.0+test (CPU build)" in done.stdout, done.stderr
    else:
        assert done.returncode != 0
        assert f"a GPU build of torch was installed (2.13.0+test, {cuda or hip})" in done.stderr
