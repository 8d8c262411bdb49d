"""Counts per command of the generated cases of :mod:`tests.scripts.fuzz_cases`: refused cleanly, reached the work
stub, contract violations (one line per category, with a reproducer). Not a test: run it before and after a change,
with the same seed and count, to compare (``tests/scripts/test_command_fuzz.py`` runs the same generator under pytest).

    OTB_ROOT=... MOT_ROOT=... python tests/scripts/fuzz_tally.py [--examples 40] [--seed 0] [--commands train smooth]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

if __package__ in (None, ""):  # run as a file: import the tests package from the repository root
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from hypothesis import HealthCheck, Phase, given, seed, settings

from tests.scripts.fuzz_cases import COMMANDS, Case, Outcome, cases, run_case, warm_up


def tally(name: str, examples: int, base_seed: int, trace: bool = False
          ) -> tuple[Counter, dict[str, tuple[Case, Outcome]], float]:
    counts: Counter = Counter()
    first: dict[str, tuple[Case, Outcome]] = {}
    warm_up(name)  # imports and first calls outside the time bound

    @seed(base_seed)
    @settings(max_examples=examples, deadline=None, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(cases(name))
    def run(case: Case) -> None:
        if trace:  # before the run: the last line names a case that killed the process
            print(f"  case: {case}", file=sys.stderr, flush=True)
        outcome = run_case(case)
        counts[outcome.kind] += 1
        if outcome.kind == "violation":
            counts[f"  {outcome.category}"] += 1
            first.setdefault(outcome.category, (case, outcome))

    start = time.perf_counter()
    run()
    return counts, first, time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--examples", type=int, default=40, help="generated cases per command")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--commands", nargs="+", choices=sorted(COMMANDS), default=list(COMMANDS))
    p.add_argument("--details", action="store_true", help="the traceback or message of each category's first case")
    p.add_argument("--trace", action="store_true", help="print each case to stderr before running it")
    args = p.parse_args(argv)
    print(f"fuzz tally: {args.examples} cases per command, seed {args.seed}")
    print(f"{'command':<22} {'refused':>7} {'reached':>7} {'violations':>10}  seconds")
    total: Counter = Counter()
    for name in args.commands:
        counts, first, seconds = tally(name, args.examples, args.seed, args.trace)
        total.update({k: v for k, v in counts.items() if not k.startswith(" ")})
        print(f"{name:<22} {counts['refused']:>7} {counts['reached']:>7} {counts['violation']:>10}  {seconds:7.1f}", flush=True)
        for category, (case, outcome) in sorted(first.items()):
            print(f"    {counts['  ' + category]:>3} x {category}\n          e.g. {case}")
            if args.details:
                print("          " + outcome.detail.strip().replace("\n", "\n          ")[-1500:])
    print(f"{'total':<22} {total['refused']:>7} {total['reached']:>7} {total['violation']:>10}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
