"""The compiled pairwise IoU (bboxtune.agents.tracking.association, ``jit.ENABLED`` on) equals its numpy reference
(iou_matrix_numpy) bit for bit: overlapping, nested, touching and disjoint boxes, zero and negative sizes, NaN and
infinite coordinates (a tracker's predictions may hold them)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune.agents.tracking.association import iou_matrix, iou_matrix_numpy
from tests.kernel_modes import both


def boxes(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 4) xywh boxes on a coarse grid (so that edges touch and boxes repeat), some sizes 0 or negative, some
    coordinates NaN or ±inf."""
    out = np.column_stack([rng.integers(0, 20, (n, 2)) * 5.0, rng.integers(-1, 6, (n, 2)) * 10.0])
    odd = rng.random((n, 4)) < 0.05
    out[odd] = rng.choice([np.nan, np.inf, -np.inf], int(odd.sum()))
    return out


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**16), n=st.integers(1, 12), m=st.integers(1, 12))
def test_iou_kernel_equals_reference(seed: int, n: int, m: int) -> None:
    rng = np.random.default_rng(seed)
    a, b = boxes(rng, n), boxes(rng, m)
    with np.errstate(invalid="ignore"):  # inf − inf in the reference's arithmetic
        kernel, reference = both(lambda: iou_matrix(a, b))
        np.testing.assert_array_equal(reference, iou_matrix_numpy(a, b))
    np.testing.assert_array_equal(kernel, reference)
    assert ((kernel >= 0) & (kernel <= 1)).all()
