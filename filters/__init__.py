"""bboxtune filters: eight batched back ends behind one interface (:data:`NAMES`), and the box Kalman filters
trackers ship, ByteTrack's and SORT's (:data:`PEER_NAMES`).

>>> import numpy as np
>>> from bboxtune import filters
>>> model = filters.constant_velocity(0.05, ndim=4)
>>> f = filters.make("ufir_cmn", model, psi=0.6, horizon=30)
>>> f.run(np.zeros((3, 100, 4))).shape
(3, 100, 8)
"""

from __future__ import annotations

from bboxtune.filters.base import Filter
from bboxtune.filters.batch import candidate_positions, one_track_positions, track_positions
from bboxtune.filters.horizon import n_opt, rule_horizon
from bboxtune.filters.model import StateSpaceModel, constant_velocity
from bboxtune.filters.registry import NAMES, PEER_NAMES, filter_class, make

__all__ = ["NAMES", "PEER_NAMES", "Filter", "StateSpaceModel", "candidate_positions", "constant_velocity",
           "filter_class", "make", "n_opt", "one_track_positions", "rule_horizon", "track_positions"]
