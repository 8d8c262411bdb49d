"""Misuse cases of the command-line scripts, run in-process through ``main(argv)``.

A case passes when the script stops before doing any work with exit status 2 (``SystemExit(2)`` or a return
value of 2), exactly one line on stderr that contains the case's ``mentions`` (the offending flag or file), no
traceback, and no file created, changed or removed under the test's temporary folder. The run happens in a
fresh working folder inside it, so default output folders (``runs/...``) count too, and with ``$OTB_ROOT``
unset unless the case sets it.

Placeholders in a case's arguments, ``mentions`` and ``env`` are replaced by paths of :class:`MisusePaths`:
``{file}`` a regular file, ``{dir}`` an existing empty folder, ``{missing}`` a path that does not exist,
``{under_file}`` a path below a regular file (an output folder that cannot be created), ``{bad_json}`` and
``{bad_yaml}`` malformed files, ``{out}`` a fresh output folder (not created).

Adding cases for a script (in its own test module, or in ``CASES`` of ``test_cli_misuse.py``)::

    from .cli_misuse import check_misuse, misuse, misuse_paths  # noqa: F401  (fixture)

    CASES = [misuse("--episodes", "0"), misuse("--model", "{missing}"), misuse(mentions="--model")]

    @pytest.mark.parametrize("case", CASES, ids=str)
    def test_misuse(case, misuse_paths, capsys):
        check_misuse(compare.main, case, misuse_paths, capsys)  # from bboxtune.agents.commands import compare

``misuse(*args)`` expects the last ``--flag`` of ``args`` in the error line; pass ``mentions=`` otherwise.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Misuse:
    """One misuse of a script: its arguments, the text its error line must contain, extra environment variables."""

    args: tuple[str, ...]
    mentions: str
    env: tuple[tuple[str, str], ...] = ()

    def __str__(self) -> str:
        env = " ".join(f"{k}={v}" for k, v in self.env)
        return " ".join([env, *self.args]).strip() or "(no arguments)"


def misuse(*args: str, mentions: str | None = None, env: dict[str, str] | None = None) -> Misuse:
    """A :class:`Misuse`; ``mentions`` defaults to the last ``--flag`` in ``args``."""
    if mentions is None:
        flags = [a for a in args if a.startswith("--")]
        if not flags:
            raise ValueError(f"misuse{args!r}: no --flag to expect in the error; pass mentions=")
        mentions = flags[-1]
    return Misuse(tuple(args), mentions, tuple(sorted((env or {}).items())))


@dataclass(frozen=True)
class MisusePaths:
    """The temporary folder of one case and the paths its placeholders stand for."""

    root: Path  # everything a misuse run could touch lives below it
    work: Path  # the working folder of the run
    names: dict[str, str]  # placeholder → path

    def format(self, text: str) -> str:
        return text.format(**self.names)


def make_misuse_paths(root: Path) -> MisusePaths:
    """Create the placeholder files and folders under ``root`` (changes no working folder or environment)."""
    file, folder, work = root / "file.txt", root / "folder", root / "work"
    file.write_text("not what any script expects\n")
    folder.mkdir()
    work.mkdir()
    (root / "bad.json").write_text('{"a": 1,\n "b": }\n')
    (root / "bad.yml").write_text("a: 1\nb: [1, 2\n")
    names = {"file": file, "dir": folder, "missing": root / "missing", "under_file": file / "out",
             "bad_json": root / "bad.json", "bad_yaml": root / "bad.yml", "out": root / "out"}
    return MisusePaths(root, work, {k: str(v) for k, v in names.items()})


@pytest.fixture
def misuse_paths(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> MisusePaths:
    """Fresh placeholder paths under ``tmp_path``; the working folder is ``tmp_path/work``; ``$OTB_ROOT`` unset."""
    paths = make_misuse_paths(tmp_path)
    monkeypatch.chdir(paths.work)
    monkeypatch.delenv("OTB_ROOT", raising=False)
    return paths


def snapshot(root: Path) -> dict[str, tuple[bool, int, int]]:
    """Every path below ``root`` → (is a folder, size, modification time in ns)."""
    out = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            st = os.lstat(os.path.join(folder, name))
            out[os.path.relpath(os.path.join(folder, name), root)] = (name in dirs, st.st_size, st.st_mtime_ns)
    return out


def check_misuse(main: Callable[[list[str]], object], case: Misuse, paths: MisusePaths,
                 capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch | None = None) -> str:
    """Run ``main`` on ``case`` and assert the misuse contract (module docstring); returns the error line."""
    argv = [paths.format(a) for a in case.args]
    if case.env:
        assert monkeypatch is not None, f"{case}: sets environment variables; pass monkeypatch"
        for key, value in case.env:
            monkeypatch.setenv(key, paths.format(value))
    before = snapshot(paths.root)
    capsys.readouterr()  # drop earlier output
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    problem = refusal_problem(code, err, before, snapshot(paths.root), [paths.format(case.mentions)])
    assert problem is None, f"{case}: {problem}"
    return err.splitlines()[0]


def refusal_problem(code: object, err: str, before: dict, after: dict, mentions: list[str]) -> str | None:
    """What breaks the misuse contract (module docstring) in a refused run, or None: its exit status ``code``,
    its stderr ``err``, :func:`snapshot` of the temporary folder before and after, and the texts of which the
    error line must contain one."""
    lines = err.splitlines()
    if code != 2:
        return f"exit status {code!r}, expected 2; stderr: {err[-500:]!r}"
    if "Traceback" in err:
        return f"traceback on stderr: {err[-2000:]}"
    if len(lines) != 1:
        return f"expected one line on stderr, got {len(lines)}: {err[-500:]!r}"
    if not any(m in lines[0] for m in mentions):
        return f"none of {mentions[:8]!r} named in {lines[0][:300]!r}"
    if after != before:
        changed = sorted(set(after.items()) ^ set(before.items()))
        return f"files were written, changed or removed: {sorted({name for name, _ in changed})[:5]}"
    return None


def run_script(name: str, *args: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """``python scripts/<name>.py ARGS`` in ``cwd`` (the timeout only catches a hang)."""
    return subprocess.run([sys.executable, str(REPO / "scripts" / f"{name}.py"), *args], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout)
