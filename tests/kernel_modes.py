"""Running a piece of code with the compiled kernels and with their numpy references (``jit.ENABLED``)."""

from collections.abc import Callable
from typing import Any

import pytest

from bboxtune.filters import jit


def both(fn: Callable[[], Any]) -> tuple[Any, Any]:
    """``fn()`` with the kernels, then with the numpy references."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(jit, "ENABLED", True)
        kernel = fn()
        mp.setattr(jit, "ENABLED", False)
        return kernel, fn()
