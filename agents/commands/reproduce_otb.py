"""``reproduce_otb.py``: the OTB part (Car4, Suv) of :mod:`bboxtune.agents.commands.reproduce` alone
(experiments: :mod:`bboxtune.agents.reproduce.otb`)."""

from __future__ import annotations

from bboxtune.agents.cli import command
from bboxtune.agents.commands import reproduce


@command
def main(argv: list[str] | None = None) -> int:
    """Run this part alone (``reproduce.py`` runs every part): see ``--help``."""
    return reproduce.main(argv, part="otb")
