"""bboxtune filters: eight batched back ends behind one interface (:data:`NAMES`), and the box Kalman filters
trackers ship, ByteTrack's and SORT's (:data:`PEER_NAMES`).

>>> import numpy as np, filters
>>> model = filters.constant_velocity(0.05, ndim=4)
>>> f = filters.make("ufir_cmn", model, psi=0.6, horizon=30)
>>> f.run(np.zeros((3, 100, 4))).shape
(3, 100, 8)
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_limits

from filters.base import Filter
from filters.batch import candidate_positions, track_positions
from filters.horizon import n_opt, rule_horizon
from filters.model import StateSpaceModel, constant_velocity
from filters.registry import NAMES, PEER_NAMES, filter_class, make

# The matrices here are tiny (2×2 per channel, FIR windows of at most a few hundred taps): a multi-threaded
# BLAS only adds hand-off overhead, and on a busy 2-core machine OpenBLAS's spinning threads made one N=160
# gain 100× slower. Importing ``filters`` therefore limits the BLAS libraries loaded so far to
# $BBOXTUNE_BLAS_THREADS threads (default 1); set it to another number to change that.
threadpool_limits(limits=int(os.environ.get("BBOXTUNE_BLAS_THREADS", "1")), user_api="blas")

__all__ = ["NAMES", "PEER_NAMES", "Filter", "StateSpaceModel", "candidate_positions", "constant_velocity",
           "filter_class", "make", "n_opt", "rule_horizon", "track_positions"]
