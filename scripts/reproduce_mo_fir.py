"""One part of ``reproduce.py`` alone: [Mo-FIR] ([Mo-FIR], docs/references.md) Table I: KF vs Kwon's FIR at δ = 0, 10.

    python scripts/reproduce_mo_fir.py --out DIR [--mc N] [--seed S] [--quick]

Writes ``DIR/reproduction_mo_fir.md`` and its figures, with the same numbers as the full run. The command is
:func:`bboxtune.agents.commands.reproduce_mo_fir.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.reproduce_mo_fir import main

if __name__ == "__main__":
    raise SystemExit(main())
