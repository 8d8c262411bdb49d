"""One part of ``reproduce.py`` alone: OTB ground truth + synthetic CMN with the papers' tuned parameters: Car4 and Suv.

    python scripts/reproduce_otb.py --out DIR [--otb-root DIR] [--mc N] [--seed S] [--quick]

Writes ``DIR/reproduction_otb.md`` and its figures, with the same numbers as the full run. The command is
:func:`bboxtune.agents.commands.reproduce_otb.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.reproduce_otb import main

if __name__ == "__main__":
    raise SystemExit(main())
