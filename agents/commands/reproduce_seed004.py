"""``reproduce_seed004.py``: the [Mo-FIR] ([Mo-FIR]) part of :mod:`agents.commands.reproduce` alone
(experiments: :mod:`agents.reproduce.mo_fir`)."""

from __future__ import annotations

from agents.commands import reproduce


def main(argv: list[str] | None = None) -> int:
    """Run this part alone (``reproduce.py`` runs every part): see ``--help``."""
    return reproduce.main(argv, part="seed004")
