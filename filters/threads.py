"""Threads of the filters: BLAS limited to one inside the filter recursions (unless ``$BBOXTUNE_BLAS_THREADS`` says
otherwise), and the nogil kernels that split their work over the cores (``$BBOXTUNE_KERNEL_THREADS``).

The matrices here are tiny (2×2 per channel, FIR windows of at most a few hundred taps): a multi-threaded BLAS
only adds hand-off overhead, and on a busy 2-core machine OpenBLAS's spinning threads made one N=160 gain 100×
slower. The limit holds only while a filter runs (:func:`limited_blas` wraps the public ``run`` / ``positions`` /
``run_from`` of every back end), so importing bboxtune leaves the process's thread settings as they were. A
process that already runs its BLAS libraries with at most that many threads (``threadpoolctl.threadpool_limits(1)``
once at its start) pays ~2 µs a library per call; otherwise each call sets and restores the count (~6 µs a library).

Work that is independent per track or channel group runs on consecutive slices of them in Python threads
(:func:`in_threads`): the window-KF scan of OFIR / OUFIR / Kwon's FIR, a batch of tracks through any back end
(:func:`bboxtune.filters.batch.track_positions`), the simulation, the observation features and the scoring of a
batch of episodes. Each slice releases the GIL in its kernels and numpy's draws, writes its own rows and computes
every track as in one thread, so the result is bit for bit the same for any thread count. Plain threads, not
numba's ``parallel=True``: its OpenMP layer (GNU libgomp) terminates a forked child that starts a parallel region,
and its workqueue layer aborts when two threads call parallel kernels at once. The threads are kept per process
(a call from one of them runs in it, without nesting) and glibc's malloc is set to keep freed memory first
(:mod:`bboxtune.filters.allocator`: the threads' heaps faulted their pages in again at every call).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache, wraps
from typing import ParamSpec, TypeVar

from threadpoolctl import ThreadpoolController

from bboxtune.filters.allocator import keep_freed_memory

ENV_VAR = "BBOXTUNE_BLAS_THREADS"
KERNEL_ENV_VAR = "BBOXTUNE_KERNEL_THREADS"
MAX_THREADS = 1024
MIN_WORK = 1 << 16  # work units per thread, at least (channel or channel-group frames, ~0.03–0.3 µs each)

P = ParamSpec("P")
R = TypeVar("R")


def blas_threads() -> int:
    """The BLAS thread count for the filters: ``$BBOXTUNE_BLAS_THREADS`` (an integer in [1, 1024]), default 1."""
    return _count(ENV_VAR, "1", "BLAS threads while a filter runs")


def kernel_threads() -> int:
    """Threads for the kernels that split their work (:func:`in_threads`): ``$BBOXTUNE_KERNEL_THREADS`` (an integer in
    [1, 1024]), default the number of CPUs this process may run on."""
    return _count(KERNEL_ENV_VAR, str(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                                      else os.cpu_count() or 1), "threads of the filters' kernels")


def _count(name: str, default: str, what: str) -> int:
    text = os.environ.get(name, default)
    if not text.strip().isdigit() or not 1 <= int(text) <= MAX_THREADS:
        raise ValueError(f"{name}={text!r}; allowed: an integer in [1, {MAX_THREADS}] ({what})")
    return int(text)


def in_threads(fn: Callable[[slice], R], n_items: int, work_per_item: int) -> list[R]:
    """``fn`` on consecutive slices of ``n_items`` items, one slice per thread — :func:`kernel_threads` threads, fewer
    when the work (``n_items × work_per_item`` units) leaves less than :data:`MIN_WORK` per thread — in the process's
    pool. One slice (``fn`` called here) for small calls and for calls from a thread of the pool (no nested pools).
    ``fn`` must release the GIL for the most part and write disjoint outputs. Results in slice order."""
    n = min(kernel_threads(), n_items, n_items * work_per_item // MIN_WORK)
    if n <= 1 or getattr(_worker, "busy", False):
        return [fn(slice(0, n_items))]
    bounds = [i * n_items // n for i in range(n + 1)]
    # every slice in the pool while the caller waits: with the caller running a slice itself (its Python parts
    # contending for the GIL with the pool's), a batched env step took ~20 % longer (4 runs, 2026-11-28)
    return list(_pool(n).map(fn, [slice(bounds[i], bounds[i + 1]) for i in range(n)]))


_worker = threading.local()  # busy: this thread is one of a pool's


def _mark_worker() -> None:
    _worker.busy = True


@lru_cache(maxsize=8)
def _pool_of(n: int, pid: int) -> ThreadPoolExecutor:
    keep_freed_memory()  # the threads' heaps keep what they free (bboxtune.filters.allocator)
    return ThreadPoolExecutor(n, thread_name_prefix="bboxtune-kernel", initializer=_mark_worker)


def _pool(n: int) -> ThreadPoolExecutor:
    """The process's pool of ``n`` threads, kept between calls (starting threads costs ~0.1 ms a call); keyed by the
    process id too, as a forked child has none of its parent's threads."""
    return _pool_of(n, os.getpid())


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
