"""Generated command lines of every command (``fuzz_cases.py``: Hypothesis-drawn flag values and file contents):
each one is refused with the misuse contract of ``cli_misuse.py`` or reaches the command's work, stubbed, having
written nothing but its output folder; each within ``CASE_SECONDS`` (the Hypothesis deadline).

The defects it found are fixed and pinned as misuse cases (:data:`FOUND`). ``fuzz_tally.py`` runs the same
generator and prints counts per command.
"""

from __future__ import annotations

import importlib
import pkgutil
import tempfile
from datetime import timedelta
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings

from bboxtune.agents import commands

from . import fuzz_files
from .cli_misuse import check_misuse, misuse
from .fuzz_cases import CASE_SECONDS, COMMANDS, Case, ReachedWork, cases, run_case, stub_reached, warm_up

EXAMPLES = 25  # per command: the whole module runs in about 40 s on 2 cores


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_generated_command_lines_are_refused_in_one_line_or_reach_the_work(name):
    warm_up(name)  # imports (torch, SB3) and first calls outside the deadline

    # too_slow / data_too_large: a case draws a value for each of up to ~25 flags and file contents for some;
    # no shrinking: a case runs a command (up to seconds), and the failure message prints the case as generated
    @settings(max_examples=EXAMPLES, deadline=timedelta(seconds=CASE_SECONDS), derandomize=True, database=None,
              phases=[Phase.explicit, Phase.generate], suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(case=cases(name))
    def check(case: Case) -> None:
        outcome = run_case(case)
        if outcome.kind == "violation":
            pytest.fail(f"{case}: {outcome.category}\n{outcome.detail}", pytrace=False)

    check()


# what the fuzz found, each a one-line refusal now: a name longer than NAME_MAX (255 bytes) in an output folder and in
# a data folder (OSError tracebacks from mkdir / exists()), and a --vec the YAML refuses blamed on the YAML file only
FOUND = [("mot_fit", misuse("--out", "{dir}/" + "n" * 300)),
         ("mot_fit", misuse("--out", "{out}", "--mot-root", "a" * 10_000)),
         ("reproduce", misuse("--quick", "--out", "{dir}/" + "n" * 300)),
         ("train", misuse("--out", "{out}", "--env", "bboxtune/FilterRetune-v0", "--vec", "batched"))]


@pytest.mark.parametrize(("name", "case"), FOUND, ids=[f"{n}: {c}"[:80] for n, c in FOUND])
def test_what_the_fuzz_found_is_refused_in_one_line(name, case, misuse_paths, capsys, monkeypatch):
    check_misuse(importlib.import_module(f"{commands.__name__}.{name}").main, case, misuse_paths, capsys, monkeypatch)


def test_every_command_is_fuzzed():
    """A new command module gets an entry in fuzz_cases.COMMANDS (its work stubs)."""
    names = {m.name for m in pkgutil.iter_modules(commands.__path__)}
    with_main = {n for n in names if hasattr(importlib.import_module(f"{commands.__name__}.{n}"), "main")}
    assert with_main == {c.module for c in COMMANDS.values()}


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_the_work_stubs_exist(name):
    """A renamed work function would leave its stub unused and the fuzz run the real work."""
    module = importlib.import_module(f"{commands.__name__}.{COMMANDS[name].module}")
    for dotted in COMMANDS[name].stubs:
        obj = module
        for part in dotted.split("."):
            obj = getattr(obj, part)
        assert callable(obj), dotted


@settings(max_examples=30, deadline=timedelta(seconds=CASE_SECONDS), derandomize=True, database=None)
@given(data=fuzz_files.json_doc() | fuzz_files.contents())
def test_sweep_json_of_a_resume_is_read_or_named(data):
    """sweep.py --resume reads DIR/sweep.json (through run_sweep, its public entry; Ray's start is stubbed)."""
    pytest.importorskip("ray")
    import ray

    from bboxtune.agents.commands.sweep import SMOKE
    from bboxtune.agents.training.runs import RunError
    from bboxtune.agents.training.sweep import run_sweep

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp).resolve()
        (out / "sweep.json").write_bytes(data)
        original, ray.init = ray.init, stub_reached
        try:
            run_sweep(SMOKE, out, resume=True)
        except ReachedWork:
            pass
        except RunError as err:
            assert str(out / "sweep.json") in str(err), err
        finally:
            ray.init = original
