"""BLAS threads inside the filter recursions: one, unless ``$BBOXTUNE_BLAS_THREADS`` says otherwise.

The matrices here are tiny (2×2 per channel, FIR windows of at most a few hundred taps): a multi-threaded BLAS
only adds hand-off overhead, and on a busy 2-core machine OpenBLAS's spinning threads made one N=160 gain 100×
slower. The limit holds only while a filter runs (:func:`limited_blas` wraps the public ``run`` / ``positions`` /
``run_from`` of every back end), so importing bboxtune leaves the process's thread settings as they were. A
process that already runs its BLAS libraries with at most that many threads (``threadpoolctl.threadpool_limits(1)``
once at its start) pays ~2 µs a library per call; otherwise each call sets and restores the count (~6 µs a library).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from functools import lru_cache, wraps
from typing import ParamSpec, TypeVar

from threadpoolctl import ThreadpoolController

ENV_VAR = "BBOXTUNE_BLAS_THREADS"
MAX_THREADS = 1024

P = ParamSpec("P")
R = TypeVar("R")


def blas_threads() -> int:
    """The BLAS thread count for the filters: ``$BBOXTUNE_BLAS_THREADS`` (an integer in [1, 1024]), default 1."""
    text = os.environ.get(ENV_VAR, "1")
    if not text.strip().isdigit() or not 1 <= int(text) <= MAX_THREADS:
        raise ValueError(f"{ENV_VAR}={text!r}; allowed: an integer in [1, {MAX_THREADS}] (BLAS threads while a filter "
                         "runs)")
    return int(text)


@lru_cache(maxsize=1)
def _controller_for(n_modules: int) -> ThreadpoolController:
    return ThreadpoolController().select(user_api="blas")  # finds the loaded BLAS libraries (about 1 ms)


def _controller() -> ThreadpoolController:
    """The BLAS libraries loaded now: looked up again only after a module was imported (a new library, e.g. scipy's
    own OpenBLAS, comes with an import)."""
    return _controller_for(len(sys.modules))


def limited_blas(method: Callable[P, R]) -> Callable[P, R]:
    """``method`` run with the BLAS libraries limited to :func:`blas_threads` threads, restored afterwards: each
    library above the count is set to it and back by its own controller (~6 µs a library; threadpoolctl's
    ``limit`` context, which also re-reads every library's info, took ~60 µs a call)."""

    @wraps(method)
    def limited(*args: P.args, **kwargs: P.kwargs) -> R:
        n, libraries = blas_threads(), _controller().lib_controllers
        above = [(lib, count) for lib in libraries if (count := lib.num_threads) > n]
        if not above:  # nothing to change (~2 µs a library)
            return method(*args, **kwargs)
        for lib, _ in above:
            lib.set_num_threads(n)
        try:
            return method(*args, **kwargs)
        finally:
            for lib, count in above:
                lib.set_num_threads(count)

    return limited
