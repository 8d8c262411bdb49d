"""bboxtune filters: eight batched back ends behind one interface.

>>> import numpy as np, filters
>>> model = filters.constant_velocity(0.05, ndim=4)
>>> f = filters.make("ufir_cmn", model, psi=0.6, horizon=30)
>>> f.run(np.zeros((3, 100, 4))).shape
(3, 100, 8)
"""

from __future__ import annotations

import os
from functools import lru_cache
from importlib import import_module
from typing import Any

from threadpoolctl import threadpool_limits

from filters.base import Filter
from filters.horizon import n_opt, rule_horizon
from filters.model import StateSpaceModel, constant_velocity

# The matrices here are tiny (2×2 per channel, FIR windows of at most a few hundred taps): a multi-threaded
# BLAS only adds hand-off overhead, and on a busy 2-core machine OpenBLAS's spinning threads made one N=160
# gain 100× slower. Importing ``filters`` therefore limits the BLAS libraries loaded so far to
# $BBOXTUNE_BLAS_THREADS threads (default 1); set it to another number to change that.
threadpool_limits(limits=int(os.environ.get("BBOXTUNE_BLAS_THREADS", "1")), user_api="blas")

NAMES: tuple[str, ...] = ("kf", "kf_cmn", "ufir", "ufir_cmn", "ofir", "oufir", "fir", "ukf")

# name -> (module, class); imported on first use
_REGISTRY: dict[str, tuple[str, str]] = {
    "kf": ("filters.kf", "KF"),
    "kf_cmn": ("filters.kf_cmn", "KFCMN"),
    "ufir": ("filters.ufir", "UFIR"),
    "ufir_cmn": ("filters.ufir_cmn", "UFIRCMN"),
    "ofir": ("filters.ofir", "OFIR"),
    "oufir": ("filters.oufir", "OUFIR"),
    "fir": ("filters.fir", "KwonFIR"),
    "ukf": ("filters.ukf", "UKF"),
}


@lru_cache(maxsize=None)
def filter_class(name: str) -> type[Filter]:
    """The :class:`Filter` subclass of back end ``name`` (one of :data:`NAMES`)."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown filter {name!r}; allowed: {', '.join(NAMES)}")
    module, cls = _REGISTRY[name]
    return getattr(import_module(module), cls)


def make(name: str, model: StateSpaceModel, **params: Any) -> Filter:
    """Configure back end ``name`` for ``model``; ``params`` as documented by its class."""
    return filter_class(name)(model, **params)


__all__ = ["NAMES", "Filter", "StateSpaceModel", "constant_velocity", "filter_class", "make", "n_opt", "rule_horizon"]
