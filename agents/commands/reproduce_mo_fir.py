"""``reproduce_mo_fir.py``: the [Mo-FIR] part of :mod:`bboxtune.agents.commands.reproduce` alone
(experiments: :mod:`bboxtune.agents.reproduce.mo_fir`)."""

from __future__ import annotations

from bboxtune.agents.cli import command
from bboxtune.agents.commands import reproduce


@command
def main(argv: list[str] | None = None) -> int:
    """Run this part alone (``reproduce.py`` runs every part): see ``--help``."""
    return reproduce.main(argv, part="mo_fir")
