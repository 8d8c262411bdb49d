"""Score real tracker outputs on OTB-100: sequence-averaged success AUC and precision at 20 px.

    python scripts/otb_eval.py --otb-root ../shared/data/otb [--tracker NAME ...] [--json]

The command is :func:`bboxtune.agents.commands.otb_eval.main`; ``--help`` describes every flag.
"""

from bboxtune.agents.commands.otb_eval import main

if __name__ == "__main__":
    raise SystemExit(main())
