"""The box Kalman filters trackers ship, with their published settings, in a tuner's place (``smooth.py --filter``).

:class:`StockFilter` answers the calls ``smooth.py`` and :mod:`bboxtune.agents.smoothing.mot_smooth` make of a
:class:`bboxtune.agents.smoothing.tuner.Tuner` (``observe``, ``params``, ``leaves_alone``, ``smooth``, ``parameters``, ``name``,
``backend``, ``gate``, ``config``) with a fixed filter: ByteTrack / DeepSORT's (``bytetrack_kf``) or SORT's
(``sort_kf``) — no parameters chosen, nothing left alone. Boxes are (T, 4) xywh px, NaN rows missing (checked as
:func:`bboxtune.agents.smoothing.tuner.check_boxes` checks them: at least 8 frames, 2 measured); frames before the first box
have no estimate (NaN rows), later
missing frames are predicted.

>>> import numpy as np
>>> boxes = np.array([[10.0 + 2 * n, 20, 30, 60] for n in range(10)])
>>> boxes[4] = np.nan
>>> smoothed = StockFilter("bytetrack_kf").smooth(boxes, 1 / 30)
>>> smoothed.shape, bool(np.isfinite(smoothed[4]).all())  # frame 4 predicted through the gap
((10, 4), True)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from bboxtune import filters
from bboxtune.agents.smoothing.tuner import check_boxes, check_tau
from bboxtune.envs.data.boxes import cxcywh_to_xywh, xywh_to_cxcywh
from bboxtune.envs.episodes.config import EnvConfig
from bboxtune.envs.episodes.scoring import detections

STOCK_FILTERS = filters.PEER_NAMES  # ("bytetrack_kf", "sort_kf")

Seen = TypeVar("Seen")


class TrackSmoother(Protocol[Seen]):
    """What ``smooth.py`` and :mod:`bboxtune.agents.smoothing.mot_smooth` ask of a tuner: a
    :class:`~bboxtune.agents.smoothing.tuner.Tuner` (``Seen`` = its ``Observation``) or a :class:`StockFilter`
    (``Seen`` = the checked track)."""

    @property
    def name(self) -> str: ...

    @property
    def backend(self) -> str: ...

    @property
    def parameters(self) -> tuple[str, ...]: ...

    @property
    def config(self) -> EnvConfig: ...

    @property
    def gate(self) -> Any: ...

    def observe(self, boxes: ArrayLike, tau: Any) -> Seen: ...

    def params(self, seen: Seen) -> dict[str, float | int]: ...

    def leaves_alone(self, seen: Seen) -> bool: ...

    def smooth(self, boxes: ArrayLike, tau: Any, params: dict[str, float | int] | None = None) -> np.ndarray: ...


@dataclass(frozen=True)
class StockFilter:
    """Back end ``backend`` (one of :data:`STOCK_FILTERS`) with its published settings."""

    backend: str
    config: EnvConfig = field(default_factory=EnvConfig)  # only its otb_tau: smooth.py's default frame interval
    gate: None = None  # never leaves a track alone
    parameters: tuple[str, ...] = ()  # none chosen

    def __post_init__(self) -> None:
        if self.backend not in STOCK_FILTERS:
            raise ValueError(f"filter {self.backend!r}; allowed: one of {STOCK_FILTERS}")

    @property
    def name(self) -> str:
        return f"stock {self.backend}"

    def observe(self, boxes: ArrayLike, tau: Any) -> tuple[np.ndarray, float]:
        """The checked track: nothing is chosen from it."""
        return check_boxes(boxes), check_tau(tau)

    def params(self, seen: tuple[np.ndarray, float]) -> dict[str, float | int]:
        return {}

    def leaves_alone(self, seen: tuple[np.ndarray, float]) -> bool:
        return False

    def smooth(self, boxes: ArrayLike, tau: Any, params: dict[str, float | int] | None = None) -> np.ndarray:
        """The track filtered with the published settings, (T, 4) xywh px (boxes with w or h below the filter's
        minimum count as missing, :func:`bboxtune.envs.episodes.scoring.detections`)."""
        y = detections(self.backend, xywh_to_cxcywh(check_boxes(boxes)))
        return cxcywh_to_xywh(filters.candidate_positions(self.backend, y, check_tau(tau), {})[0])
