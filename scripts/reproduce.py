"""Reproduce the papers' experiments and write our numbers beside theirs.

    python scripts/reproduce.py --out DIR [--otb-root DIR] [--mc N] [--seed S] [--quick]
    python scripts/reproduce_shmaliy_cmn.py --out DIR [--mc N] [--seed S] [--quick]          # one part alone;
    python scripts/reproduce_mo_fir.py ...  /  python scripts/reproduce_otb.py ... [--otb-root DIR]  # the others

The command is :func:`bboxtune.agents.commands.reproduce.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.reproduce import main

if __name__ == "__main__":
    raise SystemExit(main())
