"""Generated command lines of every command (``fuzz_cases.py``: Hypothesis-drawn flag values and file contents):
each one is refused with the misuse contract of ``cli_misuse.py`` or reaches the command's work, stubbed, having
written nothing but its output folder; each within ``CASE_SECONDS`` (the Hypothesis deadline).

Defects in code that other work owns are listed in :data:`KNOWN`: their reproducers are strict xfails (they fail
once the defect is fixed: then delete the entry), and the generated cases that show them are not failures here.
``fuzz_tally.py`` runs the same generator and prints counts per command.
"""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings

from bboxtune.agents import commands

from . import fuzz_files
from .cli_misuse import REPO
from .fuzz_cases import CASE_SECONDS, COMMANDS, Case, Outcome, ReachedWork, cases, run_case, stub_reached, warm_up

EXAMPLES = 25  # per command: the whole module runs in about 40 s on 2 cores


@dataclass(frozen=True)
class Known:
    """A defect in code that other work owns: its owner, a reproducer, and how its violations look (the start of
    :attr:`Outcome.category`, a text in :attr:`Outcome.detail`; in every command, or only the reproducer's)."""

    owner: str
    case: Case
    category: str
    detail: str = ""
    every_command: bool = False
    isolated: bool = False  # its reproducer runs in a subprocess under a memory and time limit (it hangs or swells)

    def matches(self, case: Case, outcome: Outcome) -> bool:
        return (not self.isolated and outcome.category.startswith(self.category) and self.detail in outcome.detail
                and (self.every_command or case.command == self.case.command))


LONG_NAME = "{root}/" + "n" * 300  # one path component longer than NAME_MAX (255)
KNOWN = [
    Known("agents/cli.py out_dir: accepts a name longer than NAME_MAX; the command's mkdir / exists() then raises "
          "OSError ENAMETOOLONG (also reproduce.py, sweep's check_free, mot_eval's outputs_taken)",
          Case("mot_fit", ("--out", LONG_NAME)), "OSError", "File name too long", every_command=True),
    Known("agents/cli.py existing_dir / existing_file: Path.exists() raises OSError ENAMETOOLONG on a 10 kB name",
          Case("mot_fit", ("--out", "{out}", "--mot-root", "a" * 10_000)), "OSError", "File name too long",
          every_command=True),
    Known("train.py new_config: a --vec the algorithm's YAML refuses is blamed on agents/hyperparams/<algo>.yml, "
          "not on --vec",
          Case("train", ("--out", "{out}", "--env", "bboxtune/FilterRetune-v0", "--vec", "batched")),
          "error line names no flag or file", "vec_env="),
    Known("compare.py --episodes (memory bounds helper): an allowed --episodes 1000000000 builds a plan of 10^9 "
          "episodes (agents/splits.py): MemoryError under 4 GiB, unlimited it swells until the OOM killer ends the "
          "process; fuzz_cases avoids generating it",
          Case("compare", ("--model", "{run}", "--out", "{out}", "--episodes", "1000000000")), "", isolated=True),
]
ISOLATED_LIMITS = {"memory_bytes": 4 * 2**30, "seconds": 60}


def run_isolated(case: Case) -> str:
    """run_case(case) in a fresh interpreter limited to ISOLATED_LIMITS; its outcome's kind and category, or why
    it gave none."""
    code = ("import resource, sys\n"
            f"resource.setrlimit(resource.RLIMIT_AS, ({ISOLATED_LIMITS['memory_bytes']},) * 2)\n"
            "from tests.scripts.fuzz_cases import Case, run_case\n"
            f"o = run_case(Case({case.command!r}, {case.args!r}))\n"
            "print(o.kind, o.category)\n")
    try:
        done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                              timeout=ISOLATED_LIMITS["seconds"])
    except subprocess.TimeoutExpired:
        return f"violation: no result within {ISOLATED_LIMITS['seconds']} s"
    lines = done.stdout.strip().splitlines()
    return lines[-1] if done.returncode == 0 and lines else f"violation: exit {done.returncode}: {done.stderr[-300:]}"


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
        if outcome.kind == "violation" and not any(k.matches(case, outcome) for k in KNOWN):
            pytest.fail(f"{case}: {outcome.category}\n{outcome.detail}", pytrace=False)

    check()


@pytest.mark.parametrize("known", [pytest.param(k, id=str(k.case), marks=pytest.mark.xfail(strict=True, reason=k.owner))
                                   for k in KNOWN])
def test_known_defect_is_fixed(known):
    if known.isolated:
        result = run_isolated(known.case)
        assert not result.startswith("violation"), f"{known.case}: {result}"
        return
    outcome = run_case(known.case)
    assert outcome.kind != "violation", f"{known.case}: {outcome.category}\n{outcome.detail[-1500:]}"


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


@pytest.mark.xfail(strict=True, reason="agents/training/sweep.py run_sweep (sweep helper): a malformed sweep.json of "
                   "--resume escapes as JSONDecodeError / UnicodeDecodeError (a traceback), not a RunError naming it")
@settings(max_examples=30, deadline=timedelta(seconds=CASE_SECONDS), derandomize=True, database=None)
@given(data=fuzz_files.json_doc() | fuzz_files.contents())
def test_sweep_json_of_a_resume_is_read_or_named(data):
    """sweep.py --resume reads DIR/sweep.json (through run_sweep, its public entry; Ray's start is stubbed)."""
    pytest.importorskip("ray")
    import ray

    from bboxtune.agents.commands.sweep import build_parser, spec_of
    from bboxtune.agents.training.runs import RunError
    from bboxtune.agents.training.sweep import run_sweep

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp).resolve()
        (out / "sweep.json").write_bytes(data)
        parser = build_parser()
        spec = spec_of(parser, parser.parse_args(["--out", tmp, "--resume", "--smoke"]))
        original, ray.init = ray.init, stub_reached
        try:
            run_sweep(spec, out, resume=True)
        except ReachedWork:
            pass
        except RunError as err:
            assert str(out / "sweep.json") in str(err), err
        finally:
            ray.init = original
