"""One part of ``reproduce.py`` alone: [Mo-FIR] ([Mo-FIR], docs/references.md) Table I: KF vs Kwon's FIR at δ = 0, 10.

    python scripts/reproduce_seed004.py --out DIR [--mc N] [--seed S] [--quick]

Writes ``DIR/reproduction_seed004.md`` and its figures, with the same numbers as the full run. The command is
:func:`agents.commands.reproduce_seed004.main`; ``--help`` describes every flag.
"""

from agents.commands.reproduce_seed004 import main

if __name__ == "__main__":
    raise SystemExit(main())
