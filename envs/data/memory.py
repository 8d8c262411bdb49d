"""Bounds from memory: refuse work whose arrays would not fit before allocating them.

Where a count multiplies memory (vector envs × frames, candidate actions × frames, evaluation episodes, a
training run's envs × rollout steps), the caller estimates the bytes from the shapes it is about to allocate
and calls :func:`check_fits`, which raises :class:`MemoryLimitError` — a ``ValueError`` naming the request,
the estimate and the memory available — when the estimate exceeds :func:`available_bytes`. The limits are
therefore the machine's, not fixed caps: a larger machine accepts larger requests.

:func:`available_bytes` reads ``MemAvailable`` of ``/proc/meminfo`` (Linux: free memory plus what the kernel
can reclaim without swapping); elsewhere the free physical pages (``os.sysconf``); None where neither is
known (then nothing is refused). Tests replace it (``monkeypatch.setattr(memory, "available_bytes", ...)``).

>>> check_fits(2 * GIB, "n_envs=10", available=4 * GIB)
>>> check_fits(3 * GIB, "n_envs=15", available=2 * GIB)
Traceback (most recent call last):
bboxtune.envs.data.memory.MemoryLimitError: n_envs=15 needs ~3 GiB, this machine has 2 GiB available
"""

from __future__ import annotations

import os

GIB = 2**30
MEMINFO = "/proc/meminfo"


class MemoryLimitError(ValueError):
    """A request whose estimated memory exceeds what this machine has available."""


def available_bytes() -> int | None:
    """The memory this process could still allocate without swapping, in bytes (module docstring); None if unknown."""
    try:
        with open(MEMINFO, encoding="ascii") as file:
            for line in file:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024  # kB
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def gib(n_bytes: float) -> str:
    """``n_bytes`` in GiB to 3 significant digits, e.g. ``"7.45"``."""
    return f"{n_bytes / GIB:.3g}"


def check_fits(needed: float, what: str, available: int | None = None) -> None:
    """:class:`MemoryLimitError` "``what`` needs ~X GiB, this machine has Y GiB available" when the estimate
    ``needed`` (bytes) exceeds ``available`` (default: :func:`available_bytes`; unknown: nothing is refused).
    ``what`` names the request as the user gave it (the argument or flag and its value)."""
    if available is None:
        available = available_bytes()
    if available is not None and needed > available:
        raise MemoryLimitError(f"{what} needs ~{gib(needed)} GiB, this machine has {gib(available)} GiB available")
