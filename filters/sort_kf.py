"""SORT's box Kalman filter ([Bewley-SORT]: its ``KalmanBoxTracker``), batched over tracks.

Per track, with dt = 1 frame:

* state ``[u, v, s, r, u', v', s']``: centre, area s = w h, aspect r = w / h (constant), rates of u, v, s per
  frame; ``F``: u += u', v += v', s += s'; ``H = [I, 0]``;
* start (the first detection): mean [u, v, s, r, 0, 0, 0], P₀ = diag(10, 10, 10, 10, 10⁴, 10⁴, 10⁴);
* predict: if s + s' <= 0 then s' = 0; Q = diag(1, 1, 1, 1, 0.01, 0.01, 10⁻⁴);
* update (a detection): R = diag(1, 1, 10, 10); a missing detection: predict only (SORT predicts every
  tracker each frame and updates the matched ones); frames before the first detection: NaN;
* box from a state: w = √(s r), h = s / w.

No parameters: the published constants. It runs on :class:`bboxtune.filters.bytetrack_kf.BoxKF` (four uncoupled
[coordinate, rate] blocks, the aspect's rate fixed at 0), so it shares ByteTrack's interface: exact in frame units
(``IN_FRAMES``; τ only converts the rates to units per second), output states (B, T, 8) = (cx, cy, w, h), then their
rates per second (ẇ = w s' / 2s, ḣ = h s' / 2s), and ``run_from`` with a :class:`bboxtune.filters.base.Carry` holding
[u, v, s, r, u', v', s', 0] (rates per second) and its block-diagonal covariance. Boxes need w, h > 0.

>>> import numpy as np
>>> from bboxtune import filters
>>> f = filters.make("sort_kf", filters.constant_velocity(1 / 30, ndim=4))
>>> f.run(np.array([[50.0, 60.0, 20.0, 40.0], [np.nan] * 4, [52.0, 61.0, 22.0, 40.0]]))[:, :4].round(2)
array([[50.  , 60.  , 20.  , 40.  ],
       [50.  , 60.  , 20.  , 40.  ],
       [52.  , 61.  , 21.54, 40.85]])
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from bboxtune.filters.box_state import HeightNoise
from bboxtune.filters.bytetrack_kf import BoxKF


def _column(*values: float) -> np.ndarray:
    return np.array(values)[:, None]


# SORT's constants as standard deviations: [coordinates (u, v, s, r); their rates (u', v', s', none)]
NOISE = HeightNoise(start=(np.zeros(1), np.stack([np.sqrt(_column(10, 10, 10, 10)), _column(100, 100, 100, 0)])),
                    process=(np.zeros(1), np.stack([_column(1, 1, 1, 1), _column(0.1, 0.1, 0.01, 0)])),
                    measurement=(np.zeros(1), np.sqrt(_column(1, 1, 10, 10))))
# i.e. P₀ = diag(10, 10, 10, 10, 10⁴, 10⁴, 10⁴), Q = diag(1, 1, 1, 1, 0.01, 0.01, 10⁻⁴), R = diag(1, 1, 10, 10)


class SortKF(BoxKF):
    """SORT's box Kalman filter (module docstring); no parameters."""

    name: ClassVar[str] = "sort_kf"
    DEFAULTS: ClassVar[dict[str, Any]] = {}
    PER_TRACK: ClassVar[tuple[str, ...]] = ()
    FIXED: ClassVar[tuple[int, ...]] = (3,)  # the aspect r has no rate

    def _noise(self, params: dict[str, np.ndarray]) -> HeightNoise:
        return NOISE

    def _measure(self, Y: np.ndarray) -> np.ndarray:
        z = Y.copy()  # (u, v, s, r)
        z[:, 2], z[:, 3] = Y[:, 2] * Y[:, 3], Y[:, 2] / Y[:, 3]
        return z

    def _before_predict(self, X: np.ndarray) -> None:
        s, rate = X[0, 2], X[1, 2]  # the area's mean and rate (X[0]: the means, X[1]: the rates)
        rate *= ~(s + rate <= 0)  # if s + s' <= 0 then s' = 0 (the area must not shrink through zero)

    def _to_boxes(self, S: np.ndarray) -> None:
        s = S[..., 2].copy()
        w = np.sqrt(s * S[..., 3])  # w = √(s r), h = s / w
        h = s / w
        if S.shape[-1] > 4:
            half = S[..., 6] / (2 * s)  # ẇ = w s' / 2s, ḣ = h s' / 2s
            S[..., 6], S[..., 7] = w * half, h * half
        S[..., 2], S[..., 3] = w, h


class ScaledSortKF(SortKF):
    """SORT's filter with two noise scales per track: the standard deviations of Q's rate entries (u', v', s')
    times ``velocity_noise_scale`` k_v and those of R times ``measurement_noise_scale`` k_r (P₀ and Q's coordinate
    entries unchanged; each scale within :data:`bboxtune.filters.bytetrack_kf.STD_RANGE`). k_v = k_r = 1 is
    :class:`SortKF` bit for bit. k_v sets how fast the velocity may change, k_r how much a detection is trusted
    against the prediction. The candidate family of the tracker's search tuner
    (:mod:`bboxtune.agents.tracking.search_tune`); registered as ``sort_kf_scaled`` but, like its neighbours'
    tuning knobs, not among the env back ends."""

    name: ClassVar[str] = "sort_kf_scaled"
    DEFAULTS: ClassVar[dict[str, Any]] = {"velocity_noise_scale": 1.0, "measurement_noise_scale": 1.0}
    PER_TRACK: ClassVar[tuple[str, ...]] = tuple(DEFAULTS)

    def _noise(self, params: dict[str, np.ndarray]) -> HeightNoise:
        coordinates, rates = NOISE.process[1]
        return HeightNoise(start=NOISE.start,
                           process=(NOISE.process[0], np.stack(np.broadcast_arrays(
                               coordinates, rates * params["velocity_noise_scale"]))),
                           measurement=(NOISE.measurement[0], NOISE.measurement[1] * params["measurement_noise_scale"]))
