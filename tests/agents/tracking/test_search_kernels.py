"""The compiled kernels of the search equal their numpy references: the candidate predictions (the batch filter's
own steps) and the choice of a candidate per track (numpy's scores, margin and ties), gaps, late starts and SORT's
area guard included."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.agents.tracking.search_kernels import AREA, choose_candidates, prior_means
from bboxtune.agents.tracking.search_tune import CausalSearch, SearchSettings, candidate_grid, predicted_boxes
from bboxtune.envs.data.boxes import xywh_to_cxcywh
from bboxtune.filters.sort_kf import ScaledSortKF

from ...kernel_modes import both

MODEL = filters.constant_velocity(1 / 14, ndim=4)


def _boxes(seed: int, n: int, T: int, missing: float, shrink: float) -> np.ndarray:
    """n random walks (n, T, 4) xywh, a fraction ``missing`` of frames without detection, late starts, and boxes
    that shrink by ``shrink`` px a frame (SORT's area guard fires when the predicted area would go through 0)."""
    rng = np.random.default_rng(seed)
    y = np.cumsum(rng.normal(0, 3, (n, T, 4)), axis=1) + [300.0, 200.0, 0.0, 0.0]
    sizes = np.maximum(np.array([60.0, 120.0]) - shrink * np.arange(T)[:, None], 1.0)
    y[..., 2:] = sizes * rng.uniform(0.8, 1.2, (n, 1, 2))
    y[rng.random((n, T)) < missing] = np.nan
    y[np.arange(T) < rng.integers(0, T, n)[:, None]] = np.nan
    return y


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 6), T=st.integers(1, 40), missing=st.floats(0.0, 0.6),
       shrink=st.sampled_from([0.0, 3.0, 12.0]))
def test_the_kernel_equals_the_reference(seed: int, n: int, T: int, missing: float, shrink: float) -> None:
    y = np.repeat(_boxes(seed, n, T, missing, shrink), 9, axis=0)
    grid = candidate_grid(4.0, 3)
    kf = ScaledSortKF(MODEL, **{name: np.tile(values, n) for name, values in grid.items()})
    (kernel_boxes, kernel_scored), (reference_boxes, reference_scored) = both(lambda: predicted_boxes(kf, y))
    np.testing.assert_array_equal(kernel_scored, reference_scored)
    np.testing.assert_allclose(kernel_boxes, reference_boxes, rtol=1e-9, atol=1e-9)


def test_the_guard_fires_and_matches() -> None:
    y = _boxes(1, 3, 40, 0.3, 12.0)
    kf = ScaledSortKF(MODEL)
    (kernel_boxes, scored), (reference_boxes, _) = both(lambda: predicted_boxes(kf, y))
    assert scored.sum() > 40
    np.testing.assert_allclose(kernel_boxes, reference_boxes, rtol=1e-9, atol=1e-9)
    z = np.ascontiguousarray(kf._measure(xywh_to_cxcywh(y).transpose(1, 2, 0)))
    noise = kf._noise({name: np.broadcast_to(v, (3,)) for name, v in kf.params.items()})
    fixed = [np.ascontiguousarray(np.broadcast_to(np.square(pair[1]), shape))
             for pair, shape in ((noise.start, (2, 4, 3)), (noise.process, (2, 4, 3)), (noise.measurement, (4, 3)))]
    guarded, _ = prior_means(z, *fixed, AREA)
    unguarded, _ = prior_means(z, *fixed, -1)
    assert not np.allclose(guarded[:, 2], unguarded[:, 2], equal_nan=True)  # the guard changed the area here
    np.testing.assert_allclose(guarded.transpose(2, 0, 1)[..., :2], xywh_to_cxcywh(kernel_boxes)[..., :2], rtol=1e-9)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 6), T=st.integers(2, 128), missing=st.floats(0.0, 0.7),
       shrink=st.sampled_from([0.0, 3.0, 12.0]), cap=st.sampled_from([1e-3, 0.5, 1.0]),
       margin=st.sampled_from([0.0, 0.01, 1.0]), min_scored=st.integers(1, 8))
def test_the_choice_kernel_equals_the_reference(seed: int, n: int, T: int, missing: float, shrink: float, cap: float,
                                                margin: float, min_scored: int) -> None:
    search = CausalSearch(1 / 14, SearchSettings(history=T, cap=cap, margin=margin, min_scored=min_scored))
    y = _boxes(seed, n, T, missing, shrink)
    chosen = choose_candidates(y, *search._variances, AREA, cap, margin, search.stock, min_scored)
    np.testing.assert_array_equal(chosen, search._reference_choice(y))


def test_the_choice_kernel_leaves_the_stock_candidate() -> None:
    search = CausalSearch(1 / 14, SearchSettings(history=60, min_scored=3))
    y = _boxes(4, 12, 60, 0.2, 3.0)
    chosen = choose_candidates(y, *search._variances, AREA, 0.5, 0.0, search.stock, 3)
    assert (chosen != search.stock).any()  # the comparison above is not only of stock choices
    np.testing.assert_array_equal(chosen, search._reference_choice(y))
