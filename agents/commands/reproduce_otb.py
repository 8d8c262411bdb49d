"""``reproduce_otb.py``: the OTB part (Car4, Suv) of :mod:`agents.commands.reproduce` alone
(experiments: :mod:`agents.reproduce.otb`)."""

from __future__ import annotations

from agents.commands import reproduce


def main(argv: list[str] | None = None) -> int:
    """Run this part alone (``reproduce.py`` runs every part): see ``--help``."""
    return reproduce.main(argv, part="otb")
