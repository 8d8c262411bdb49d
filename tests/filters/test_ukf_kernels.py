"""The compiled sigma-point gain recursion (bboxtune.filters.ukf_kernels) equals its numpy reference
(bboxtune.filters.ukf.sigma_gain_recursion with the kernels off) to ≤ 1e-9 relative: on gappy tracks (40–60 % of
the frames missing in runs), carried starts and random frame kinds (WAIT / INIT resets between updates), over the
whole range of α, β, κ; its steady-state stop; and its hand-over to the reference where a covariance has no
Cholesky root."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters import jit, ukf_kernels
from bboxtune.filters import kalman_core as kc
from bboxtune.filters.ukf import sigma_gain_recursion
from tests.filters.test_kalman_kernels import assert_close, gappy_mask

AXIS = filters.constant_velocity(1 / 30).axis()


def reference(kinds: np.ndarray, params: np.ndarray, P_start: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(jit, "ENABLED", False)
        return sigma_gain_recursion(kinds, params, P_start, AXIS)


def compiled(kinds: np.ndarray, params: np.ndarray, P_start: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
    out = ukf_kernels.sigma_gain_recursion(kinds, params, P_start, AXIS.F, AXIS.B[:, 0])
    assert out is not None
    return out


def random_rows(rng: np.random.Generator, G: int) -> tuple[np.ndarray, np.ndarray]:
    """Parameters [σ_w, σ_v, α, β, κ] (G, 5) across their ranges and definite start covariances (2, 2, G)."""
    params = np.stack([10.0 ** rng.uniform(-1, 4, G), 10.0 ** rng.uniform(-1, 2, G), 10.0 ** rng.uniform(-4, 4, G),
                       rng.choice([0.0, 2.0, 1e3], G), rng.choice([-1.9, 0.0, 1.0, 1e3], G)], axis=1)
    P_start = np.zeros((2, 2, G))
    P_start[0, 0], P_start[1, 1] = params[:, 1] ** 2, 1e6 * params[:, 1] ** 2 / AXIS.tau**2
    P_start[0, 1] = P_start[1, 0] = rng.uniform(-0.5, 0.5, G) * np.sqrt(P_start[0, 0] * P_start[1, 1])
    return params, P_start


def assert_same_gains(kinds: np.ndarray, params: np.ndarray, P_start: np.ndarray) -> None:
    coef, steady, P_end = compiled(kinds, params, P_start)
    coef_ref, steady_ref, P_ref = reference(kinds, params, P_start)
    assert coef.shape == coef_ref.shape and P_end.shape == P_ref.shape
    assert steady == steady_ref
    assert_close(coef, coef_ref)
    assert_close(P_end, P_ref)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), G=st.integers(1, 5), T=st.integers(1, 150),
       prior=st.sampled_from(["no", "yes", "some"]), carried=st.booleans())
def test_kernel_equals_reference_on_gappy_tracks(seed: int, G: int, T: int, prior: str, carried: bool) -> None:
    rng = np.random.default_rng(seed)
    with_prior = {"no": False, "yes": True, "some": rng.random(G) < 0.5}[prior]
    measured = rng.random(G) < 0.5 if carried else None
    kinds = kc.frame_kinds(gappy_mask(rng, G, T), with_prior, measured)
    assert_same_gains(kinds, *random_rows(rng, G))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), G=st.integers(1, 4), T=st.integers(1, 60))
def test_kernel_equals_reference_on_random_kinds(seed: int, G: int, T: int) -> None:
    """Any kind at any frame: WAIT / INIT resets between updates and predictions."""
    rng = np.random.default_rng(seed)
    kinds = rng.integers(kc.WAIT, kc.UPDATE_Y + 1, (G, T)).astype(np.int8)
    assert_same_gains(kinds, *random_rows(rng, G))


@pytest.mark.parametrize("G", [1, 3])
def test_kernel_stops_at_the_references_steady_frame(G: int) -> None:
    """Rows settling at different frames, the last after a late run of missing frames: the kernel stops where the
    reference stops, and every later frame repeats the steady one."""
    params = np.array([[50.0, 4.0, 1.0, 2.0, 0.0], [1000.0, 4.0, 1e-3, 2.0, 0.0], [50.0, 0.5, 0.7, 0.0, 1.0]])[:G]
    P_start = np.zeros((2, 2, G))
    P_start[0, 0], P_start[1, 1] = params[:, 1] ** 2, 1e6 * params[:, 1] ** 2 / AXIS.tau**2
    kinds = np.full((G, 1000), kc.UPDATE_Y, np.int8)
    kinds[:, 0] = kc.INIT
    kinds[-1, 200:230] = kc.PREDICT
    coef, steady, _ = compiled(kinds, params, P_start)
    assert 230 <= steady < 1000 and np.all(coef[steady:] == coef[steady])
    assert_same_gains(kinds, params, P_start)


def test_kernel_hands_a_singular_covariance_to_the_reference() -> None:
    """A singular start covariance has no Cholesky root: the kernel gives up, and the recursion (kernels on) gives
    the reference's result, which takes the eigen-square-root there."""
    kinds = kc.frame_kinds(np.ones((2, 20), bool), prior=True)
    params = np.array([[50.0, 4.0, 1.0, 2.0, 0.0]] * 2)
    P_start = np.stack([np.diag([16.0, 0.0]), np.diag([16.0, 1e4])], axis=2)
    assert ukf_kernels.sigma_gain_recursion(kinds, params, P_start, AXIS.F, AXIS.B[:, 0]) is None
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(jit, "ENABLED", True)
        coef, steady, P_end = sigma_gain_recursion(kinds, params, P_start, AXIS)
    coef_ref, steady_ref, P_ref = reference(kinds, params, P_start)
    assert steady == steady_ref
    np.testing.assert_array_equal(coef, coef_ref)
    np.testing.assert_array_equal(P_end, P_ref)
