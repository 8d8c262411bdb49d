"""Every docstring example of the package runs, imported by its namespace name (``bboxtune.filters.kf``, ...).

pytest's ``--doctest-modules`` would import the source folders as top-level ``filters``, ``envs`` and ``agents``: a
second copy of each module, and a second registration of the env ids."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import bboxtune
from bboxtune import agents, envs, filters


def _modules() -> list[str]:
    names = ["bboxtune"]
    for package in (filters, envs, agents):
        names.append(package.__name__)
        names += [m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")]
    return sorted(names)


MODULES = _modules()


def test_the_walk_finds_every_module() -> None:
    assert {"bboxtune.filters.kf", "bboxtune.envs.data.otb", "bboxtune.agents.commands.train"} <= set(MODULES)
    assert bboxtune.__name__ == "bboxtune"


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name: str) -> None:
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)  # as pytest's default
    for test in finder.find(module, name):
        runner.run(test)
    results = runner.summarize(verbose=False)
    assert results.failed == 0, f"{name}: {results.failed} of {results.attempted} docstring examples failed (above)"
