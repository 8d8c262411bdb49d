"""One part of ``reproduce.py`` alone: [Shmaliy-CMN] ([Shmaliy-CMN], docs/references.md): Fig. 2 and the measured
N_opt(ψ) of UFIR-CMN.

    python scripts/reproduce_shmaliy_cmn.py --out DIR [--mc N] [--seed S] [--quick]

Writes ``DIR/reproduction_shmaliy_cmn.md`` and its figures, with the same numbers as the full run. The command is
:func:`bboxtune.agents.commands.reproduce_shmaliy_cmn.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.reproduce_shmaliy_cmn import main

if __name__ == "__main__":
    raise SystemExit(main())
