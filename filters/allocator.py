"""glibc's malloc set up for batch work: the memory a batch frees is kept for the next one.

A step of the batched env (:mod:`bboxtune.envs.vector`) allocates and frees tens of 1–4 MB arrays. By default glibc
serves such blocks with ``mmap``, or trims them off the top of a heap, and returns the pages on ``free``; the next
step faults every page in again. Measured on the 2-core machine (256 envs × 500 frames, ufir_cmn): ~2,900 minor page
faults a step, 6.8 ms of system time, on one thread; with the kernels in threads (:mod:`bboxtune.filters.threads`),
whose malloc arenas shrink their heaps the same way, ~14,000 faults and ~34 ms of system time a step, more than the
threads saved. :func:`keep_freed_memory` sets, once per process, through ``mallopt``:

* ``M_MMAP_THRESHOLD`` 32 MiB (glibc's largest): blocks up to it come from a heap, not from fresh mappings;
* ``M_TRIM_THRESHOLD`` 1 GiB: a heap keeps the memory freed at its top for the next allocation unless more than
  1 GiB is free.

Then a step faults ~0–100 pages in (measured, with and without threads). The cost: the process keeps the memory it
freed, up to 1 GiB a heap, for reuse — its resident size stays near its peak rather than shrinking between batches.
(Also capping the arenas at one, ``M_ARENA_MAX``, made no difference we could measure: left alone.)

It is called where batches run (``bboxtune.envs.vector.TuneBatch``, the first pool of kernel threads). The setting
is process-wide: ``$BBOXTUNE_MALLOC=default`` leaves malloc as it is (``tuned``, the default, sets it); on a C library
other than glibc nothing changes.
"""

from __future__ import annotations

import ctypes
import os
from functools import lru_cache

ENV_VAR = "BBOXTUNE_MALLOC"
CHOICES = ("tuned", "default")
# mallopt's parameter numbers (glibc's malloc.h) and the values set
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
SETTINGS = ((M_MMAP_THRESHOLD, 32 * 2**20), (M_TRIM_THRESHOLD, 2**30))


def malloc_choice() -> str:
    """``$BBOXTUNE_MALLOC``: ``tuned`` (the default) or ``default``."""
    text = os.environ.get(ENV_VAR, "tuned").strip()
    if text not in CHOICES:
        raise ValueError(f"${ENV_VAR}={text!r} is invalid: allowed {', '.join(CHOICES)} (module bboxtune.filters.allocator)")
    return text


def keep_freed_memory() -> bool:
    """Set glibc's malloc as the module docstring says, once per process; whether it is set (False with
    ``$BBOXTUNE_MALLOC=default`` or without glibc)."""
    return malloc_choice() == "tuned" and _set_glibc_malloc()


@lru_cache(maxsize=1)
def _set_glibc_malloc() -> bool:
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the process's own C library
    except (OSError, AttributeError):  # none loadable, or one without mallopt
        return False
    return all(mallopt(parameter, value) == 1 for parameter, value in SETTINGS)
