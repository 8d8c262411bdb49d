"""One part of ``reproduce.py`` alone: [Shmaliy-CMN] ([Shmaliy-CMN], docs/references.md): Fig. 2 and the measured N_opt(ψ) of UFIR-CMN.

    python scripts/reproduce_seed000.py --out DIR [--mc N] [--seed S] [--quick]

Writes ``DIR/reproduction_seed000.md`` and its figures, with the same numbers as the full run. The command is
:func:`agents.commands.reproduce_seed000.main`; ``--help`` describes every flag.
"""

from agents.commands.reproduce_seed000 import main

if __name__ == "__main__":
    raise SystemExit(main())
