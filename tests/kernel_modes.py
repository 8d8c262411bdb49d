"""Running a piece of code with the compiled kernels and with their numpy references (``jit.ENABLED``), and counting
how the kernel threads split it."""

from collections.abc import Callable
from typing import Any

import pytest

from bboxtune.filters import jit, threads


def both(fn: Callable[[], Any]) -> tuple[Any, Any]:
    """``fn()`` with the kernels, then with the numpy references."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(jit, "ENABLED", True)
        kernel = fn()
        mp.setattr(jit, "ENABLED", False)
        return kernel, fn()


def counting_splits(counts: list[int]) -> Callable[[Callable[[slice], Any], int, int], list[Any]]:
    """``threads.in_threads`` that appends each call's slice count to ``counts`` (to patch in where it is called)."""
    split = threads.in_threads

    def counted(fn: Callable[[slice], Any], n_items: int, work_per_item: int) -> list[Any]:
        out = split(fn, n_items, work_per_item)
        counts.append(len(out))
        return out

    return counted
