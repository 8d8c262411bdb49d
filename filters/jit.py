"""Compiled kernels: numba's ``njit`` with the project's settings, and the switch between kernels and references.

The hot loops over time (the Kalman recursions, the FIR window scans, the Gauss–Markov simulation, the scoring) run
as numba kernels. Each kernel keeps its numpy implementation beside it as the tested reference: the property tests
(``tests/**/test_*kernels*.py``) check every kernel against it to ≤ 1e-9 relative on random inputs with gaps.

``$BBOXTUNE_JIT`` picks one of them for the whole process: ``1`` (default) the compiled kernels, ``0`` the numpy
references (to debug, or to compare). Kernels are compiled on first call and cached on disk (``cache=True``: next to
the sources in ``__pycache__``, or numba's user cache folder where that is read-only; ``$NUMBA_CACHE_DIR`` moves it),
so a process pays the compile time once per machine. ``nogil=True`` lets threads run them side by side.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

ENV_VAR = "BBOXTUNE_JIT"
Fn = TypeVar("Fn", bound=Callable[..., Any])


def _from_environment() -> bool:
    text = os.environ.get(ENV_VAR, "1").strip()
    if text not in ("0", "1"):
        raise ValueError(f"${ENV_VAR}={text!r} is invalid: allowed 0 (the numpy references) or 1 (the compiled "
                         "kernels, the default)")
    return text == "1"


ENABLED = _from_environment()


def enabled() -> bool:
    """Whether the compiled kernels run (``$BBOXTUNE_JIT``, read once at import; tests monkeypatch ``ENABLED``)."""
    return ENABLED


def kernel(fn: Fn | None = None, *, parallel: bool = False, inline: bool = False) -> Any:
    """``numba.njit`` with ``cache=True, nogil=True`` (and ``parallel`` for ``numba.prange`` loops); no fastmath, so a
    kernel computes what its numpy reference computes, NaN and inf included. ``inline``: a small helper compiled into
    each kernel that calls it (numba's ``inline="always"``: faster calls, longer compiles). Use as ``@kernel``,
    ``@kernel(parallel=True)`` or ``@kernel(inline=True)``."""
    def wrap(f: Fn) -> Fn:
        return cast("Fn", numba.njit(cache=True, nogil=True, parallel=parallel, inline="always" if inline else "never")(f))
    return wrap if fn is None else wrap(fn)
