"""``reproduce_seed000.py``: the [Shmaliy-CMN] ([Shmaliy-CMN]) part of :mod:`agents.commands.reproduce` alone
(experiments: :mod:`agents.reproduce.shmaliy_cmn`)."""

from __future__ import annotations

from agents.commands import reproduce


def main(argv: list[str] | None = None) -> int:
    """Run this part alone (``reproduce.py`` runs every part): see ``--help``."""
    return reproduce.main(argv, part="seed000")
