"""Every script in scripts/ is a thin command line: its docstring, ``from bboxtune.agents.commands.<name> import main`` and
the ``__main__`` guard, with no ``sys.path`` edits; every ``[project.scripts]`` entry point resolves to a ``main``."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib", reason="tomllib (Python >= 3.11) reads pyproject.toml")

REPO = Path(__file__).resolve().parents[2]
SCRIPTS = sorted((REPO / "scripts").glob("*.py"))
ENTRY_POINTS = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_no_script_edits_sys_path(script: Path) -> None:
    assert "sys.path" not in script.read_text()


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_script_is_docstring_import_and_main_guard(script: Path) -> None:
    tree = ast.parse(script.read_text())
    doc, imported, guard = tree.body
    assert isinstance(doc, ast.Expr) and f"scripts/{script.name}" in ast.get_docstring(tree)  # its usage text
    assert isinstance(imported, ast.ImportFrom) and imported.module == f"bboxtune.agents.commands.{script.stem}"
    assert [(a.name, a.asname) for a in imported.names] == [("main", None)]
    assert isinstance(guard, ast.If) and ast.unparse(guard) == "if __name__ == '__main__':\n    raise SystemExit(main())"


@pytest.mark.parametrize("name", sorted(ENTRY_POINTS))
def test_entry_point_resolves_to_a_main(name: str) -> None:
    module_name, _, function = ENTRY_POINTS[name].partition(":")
    main = getattr(importlib.import_module(module_name), function)
    assert function == "main" and callable(main)
    inspect.signature(main).bind(["--help"])  # main(argv)
    assert (REPO / "scripts" / f"{module_name.rsplit('.', 1)[1]}.py").is_file()  # the same command as a script


def test_every_user_facing_script_has_an_entry_point() -> None:
    """The benchmarks are run from a checkout only; every other script is also a console script."""
    commands = {target.partition(":")[0].rsplit(".", 1)[1] for target in ENTRY_POINTS.values()}
    assert commands == {p.stem for p in SCRIPTS if not p.stem.startswith("bench_")}
