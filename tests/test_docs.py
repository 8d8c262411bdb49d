"""README.md and the documentation site (docs/): the README's length and section order, every code block of it
(the Python blocks run, the shell commands parse), and the Sphinx build with warnings as errors.

The README's shell commands are checked without running them: the two set-up commands are the ones CI runs
(``.ci/run``), ``pip install`` lines name the CPU torch index and existing extras, and every
``python scripts/<name>.py ARGS`` line is parsed by that command's own argument parser (the data paths it names need
not exist). The same parse runs over the command lines of the docs pages.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any
from unittest import mock

import pytest

import bboxtune
from bboxtune import filters

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"

MAX_LINES = 250
# The README's sections, in the agreed order: what it is (under the title), the two set-up commands, pip
# install, the env example, the headline table, smoothing, the short reference tables, layout, citation, license.
SECTIONS = ["Quick start (fresh machine)", "Install into your own environment", "The environments in ten lines",
            "Results", "Smoothing your tracker's output", "Reference", "Layout", "Citation", "License"]
SETUP_COMMANDS = ["bash scripts/setup.sh && .venv/bin/python scripts/train.py",
                  "bash scripts/setup.sh && .venv/bin/python -m pytest -q"]
TORCH_CPU_INDEX = "https://download.pytorch.org/whl/cpu"
DATA_DEFAULTS = {"OTB_ROOT": "../shared/data/otb", "MOT_ROOT": "../shared/data/mot15"}
PLACEHOLDERS = {"S": "0"}  # the docs' "--seed S": one seed of several


def blocks(text: str) -> list[tuple[str, str]]:
    """The fenced code blocks of a Markdown text: (language, code)."""
    return [(m.group(1), m.group(2)) for m in re.finditer(r"^```(\w*)[^\n]*\n(.*?)^```\s*$", text, re.S | re.M)]


def sections(text: str) -> list[tuple[str, str]]:
    """The ``## `` sections of a Markdown text outside code blocks: (title, body)."""
    outside = re.sub(r"^```.*?^```\s*$", "", text, flags=re.S | re.M)
    parts = re.split(r"^## (.+)$", outside, flags=re.M)
    return list(zip(parts[1::2], parts[2::2], strict=False))


def command_lines(code: str) -> list[str]:
    """A shell block's commands: continuation lines joined, comments and blank lines dropped."""
    joined = re.sub(r"\\\n\s*", " ", code)
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def expand(line: str) -> str:
    """$OTB_ROOT / $MOT_ROOT (and other variables) as the environment has them, else their CI defaults."""
    return re.sub(r"\$\{?(\w+)\}?", lambda m: os.environ.get(m.group(1), DATA_DEFAULTS.get(m.group(1), m.group(0))), line)


README_TEXT = README.read_text(encoding="utf-8")
README_BLOCKS = blocks(README_TEXT)


# --- (a) length and order ---------------------------------------------------------------------------------------

def test_readme_is_short() -> None:
    assert len(README_TEXT.splitlines()) <= MAX_LINES


def test_readme_sections_are_in_the_agreed_order() -> None:
    assert README_TEXT.startswith("# bboxtune\n")
    assert [title for title, _ in sections(README_TEXT)] == SECTIONS
    intro = README_TEXT.split("\n## ", 1)[0]
    assert re.search(r"^!\[[^\]]+\]\(docs/[^)]+\.png\)$", intro, re.M), "one figure under the title"
    assert (ROOT / re.search(r"\]\((docs/[^)]+\.png)\)", intro).group(1)).is_file()


def test_readme_links_point_at_files_that_exist() -> None:
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README_TEXT):
        if "://" not in target:
            assert (ROOT / target).exists(), target


def test_readme_reference_tables_cover_the_env_ids_filters_and_commands() -> None:
    reference = dict(sections(README_TEXT))["Reference"]
    for env_id in bboxtune.ENV_IDS:
        assert f"| `{env_id}` |" in reference
    for name in filters.NAMES + filters.PEER_NAMES:
        assert f"| `{name}` |" in reference
    for script in sorted((ROOT / "scripts").glob("*.py")):
        assert script.stem + ".py" in reference, script.name


def _resolves(name: str) -> bool:
    """Whether a dotted ``bboxtune.…`` name is a module, or an attribute reached from the longest module prefix."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            if not hasattr(obj, part):
                return False
            obj = getattr(obj, part)
        return True
    return False


PAGES = [README, *sorted(DOCS.glob("*.md"))]


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_code_names_and_paths_in_the_pages_exist(page: Path) -> None:
    """Every ``bboxtune.…`` name and every repository path (``agents/…``, ``scripts/…``, ``docs/…``) written as code
    in the README and the docs pages exists, so a module or file that moves is caught here."""
    names, paths = set(), set()
    for span in re.findall(r"`([^`\n]+)`", page.read_text(encoding="utf-8")):
        names.update(re.findall(r"\bbboxtune(?:\.[A-Za-z_]\w*)+", span))
        paths.update(p.rstrip(".,;:)") for p in re.findall(
            r"(?<![\w./$-])((?:agents|envs|filters|scripts|tests|bboxtune|docs)/[\w./-]*)", span))
    missing = sorted(n for n in names if not _resolves(n))
    outputs = ("docs/_build",)  # where a command writes, not a file of the repository
    missing += sorted(p for p in paths if not (ROOT / p).exists() and p not in bboxtune.ENV_IDS
                      and not p.startswith(outputs))
    assert missing == []


# --- (b) the Python blocks run ----------------------------------------------------------------------------------

PYTHON_BLOCKS = [code for lang, code in README_BLOCKS if lang == "python"]


def test_readme_has_the_env_example() -> None:
    env_example = dict(sections(README_TEXT))  # the block sits in "The environments in ten lines"
    assert "The environments in ten lines" in env_example
    example = next(code for code in PYTHON_BLOCKS if 'gym.make("bboxtune/FilterTune-v0")' in code)
    assert len(example.strip().splitlines()) <= 10 and "import bboxtune" in example


@pytest.mark.parametrize("code", PYTHON_BLOCKS, ids=[f"python-block-{i}" for i in range(len(PYTHON_BLOCKS))])
def test_readme_python_block_runs(code: str) -> None:
    """In a fresh interpreter, from the repository root, without the data sets (no block may need them)."""
    env = {k: v for k, v in os.environ.items() if k not in DATA_DEFAULTS}
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-4000:]


# --- (c) the shell commands -------------------------------------------------------------------------------------

def test_the_setup_commands_are_the_ones_ci_runs() -> None:
    quick_start = [code.strip() for lang, code in blocks(README_TEXT.split("\n## ", 2)[1]) if lang == "bash"]
    assert quick_start == SETUP_COMMANDS
    assert SETUP_COMMANDS[1] in (ROOT / ".ci" / "run").read_text().splitlines()


class _Parsed(Exception):
    def __init__(self, namespace: argparse.Namespace) -> None:
        super().__init__("parsed")
        self.namespace = namespace


_PATH_TYPES = {"existing_dir", "existing_file", "existing_path", "out_dir"}


def _is_path_type(kind: Any) -> bool:
    """argparse ``type=`` checks that look at the file system (agents.cli and the commands' own)."""
    return getattr(kind, "__name__", "") in _PATH_TYPES or getattr(kind, "__qualname__", "").startswith("_document.")


def parse_command(script: str, args: list[str]) -> argparse.Namespace:
    """``args`` parsed by the parser that ``scripts/<script>.py`` builds (its command's ``main``), paths unchecked;
    nothing of the command runs after the parse. A parse error fails the test with the parser's message."""
    module = importlib.import_module(f"bboxtune.agents.commands.{script}")
    parse_args = argparse.ArgumentParser.parse_args

    def capture(parser: argparse.ArgumentParser, argv: Any = None, namespace: Any = None) -> argparse.Namespace:
        for action in parser._actions:
            if _is_path_type(action.type):
                action.type = str
        raise _Parsed(parse_args(parser, argv, namespace))

    with mock.patch.object(argparse.ArgumentParser, "parse_args", capture):
        try:
            module.main(args)
        except _Parsed as parsed:
            return parsed.namespace
        except SystemExit as exc:
            pytest.fail(f"scripts/{script}.py {shlex.join(args)}: the parser refused it (exit {exc.code})")
    pytest.fail(f"scripts/{script}.py: main() returned without parsing its arguments")


def check_command(line: str, pyproject: dict) -> str:
    """Checks one shell command of the README; returns what kind it was."""
    if line in SETUP_COMMANDS:
        return "setup"
    words = shlex.split(expand(line), comments=True)
    if words[:2] == ["pip", "install"]:
        rest = words[2:]
        if "torch" in rest:
            assert rest[rest.index("--index-url") + 1] == TORCH_CPU_INDEX
            return "pip"
        for word in rest:
            if word == "-e":
                continue
            target = re.fullmatch(r"\.(?:\[([\w,-]+)\])?", word)
            assert target, f"pip install of something else than this checkout: {word!r}"
            for extra in filter(None, (target.group(1) or "").split(",")):
                assert extra in pyproject["project"]["optional-dependencies"], extra
        return "pip"
    if len(words) >= 2 and words[0] == "python" and re.fullmatch(r"scripts/\w+\.py", words[1]):
        script = Path(words[1]).stem
        assert (ROOT / words[1]).is_file()
        parse_command(script, words[2:])
        return "script"
    pytest.fail(f"a README command this test does not know how to check: {line!r}")


def test_readme_shell_commands_are_valid(capsys: pytest.CaptureFixture[str]) -> None:
    tomllib = pytest.importorskip("tomllib", reason="tomllib (Python >= 3.11) reads pyproject.toml")
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert any(dep.replace(" ", "") == "torch>=2.3" for dep in pyproject["project"]["dependencies"])
    assert "torch>=2.3" in README_TEXT
    kinds = [check_command(line, pyproject) for lang, code in README_BLOCKS if lang in ("bash", "sh", "shell")
             for line in command_lines(code)]
    assert kinds.count("setup") == 2 and "pip" in kinds and "script" in kinds


def _docs_script_lines() -> list[tuple[str, str]]:
    lines = []
    for page in sorted(DOCS.glob("*.md")):
        for lang, code in blocks(page.read_text(encoding="utf-8")):
            if lang in ("bash", "sh", "shell"):
                lines += [(page.name, line) for line in command_lines(code)
                          if line.startswith("python scripts/") and "..." not in line.split()]
    return lines


DOCS_SCRIPT_LINES = _docs_script_lines()


@pytest.mark.parametrize(("page", "line"), DOCS_SCRIPT_LINES,
                         ids=[f"{page}:{i}" for i, (page, _) in enumerate(DOCS_SCRIPT_LINES)])
def test_docs_script_commands_parse(page: str, line: str) -> None:
    """The ``python scripts/<name>.py`` lines of the docs pages (a line with a ``...`` placeholder is skipped)."""
    for command in line.split(" && "):
        words = [PLACEHOLDERS.get(word, word) for word in shlex.split(expand(command), comments=True)]
        assert words[0] == "python" and (ROOT / words[1]).is_file(), command
        parse_command(Path(words[1]).stem, words[2:])


# --- (d) the site builds without a warning ----------------------------------------------------------------------

def test_sphinx_build_has_no_warnings(tmp_path: Path) -> None:
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    pytest.importorskip("furo")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-6000:]
    assert "WARNING" not in done.stderr and "ERROR" not in done.stderr, done.stderr[-6000:]
    assert (tmp_path / "html" / "index.html").is_file()
