"""The compiled Kalman kernels (bboxtune.filters.kalman_kernels) equal their numpy references in kalman_core and
kf_cmn to ≤ 1e-9 relative: the frame kinds, KF-CMN's differencing (frame kinds across gaps, measurements), the gain
recursion on the frame kinds and step tables KF / KF-CMN build from gappy tracks (40–60 % of the frames missing in
runs, carried starts) and on random tables, its steady-state stop, the affine application, whole filters (kf,
kf_cmn, ukf) run with the kernels on and off, and the filters' check of their estimates (finite_check)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters import jit
from bboxtune.filters import kalman_core as kc
from bboxtune.filters import kalman_kernels as kk
from bboxtune.filters.finite_check import first_nonfinite, first_nonfinite_numpy
from bboxtune.filters.kf import axis_matrices
from bboxtune.filters.kf_cmn import cmn_tables, differenced_kinds
from tests.filters.test_cmn_gaps import runs_missing
from tests.kernel_modes import both

AXIS = filters.constant_velocity(0.05).axis()
RTOL = 1e-9


def assert_close(got: np.ndarray, want: np.ndarray) -> None:
    """Equal to ``RTOL`` relative, NaN where the reference has NaN (an absolute floor of 1e-12 × the largest entry)."""
    scale = np.max(np.abs(want[np.isfinite(want)]), initial=0.0)
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=1e-12 * scale)


def gappy_mask(rng: np.random.Generator, G: int, T: int) -> np.ndarray:
    """Finite-measurement masks (G, T): runs of missing and seen frames, 40–60 % missing (short tracks: any), one row
    never measured when G > 2."""
    finite = np.ones((G, T), bool)
    for g in range(G):
        for _ in range(20):
            edges = np.cumsum(rng.integers(1, 12, T))
            seen = (np.searchsorted(edges, np.arange(T), side="right") + rng.integers(2)) % 2 == 0
            if T < 10 or 0.4 <= 1.0 - seen.mean() <= 0.6:
                break
        finite[g] = seen
    if G > 2:
        finite[-1] = False
    return finite


def differencing_case(rng: np.random.Generator, G: int, T: int, carried: bool) -> tuple[np.ndarray, ...]:
    """The inputs of ``differenced_kinds`` on G gappy tracks as ``kf_cmn`` builds them (``carried``: a continued run —
    priors, carried last measurements and frames missed since): kinds, z, finite, y_before, missed, psi."""
    finite = gappy_mask(rng, G, T)
    z = np.where(finite, rng.normal(100.0, 20.0, (G, T)), np.nan)
    psi = rng.choice([0.0, 0.3, 0.9, 0.99], G)
    prior = rng.random(G) < 0.5 if carried else False
    measured = (rng.random(G) < 0.5) & prior if carried else None
    kinds = kc.frame_kinds(finite, prior, measured)
    y_before = np.where(measured, rng.normal(100.0, 20.0, G), np.nan) if carried else np.full(G, np.nan)
    missed = rng.integers(0, 5, G) if carried else np.zeros(G, np.int64)
    return kinds, z, finite, y_before, missed, psi


def cmn_case(seed: int, G: int, T: int, carried: bool) -> tuple[np.ndarray, kc.StepTables, np.ndarray]:
    """Frame kinds, step tables and start covariances of G KF-CMN rows on gappy tracks (:func:`differencing_case`)."""
    rng = np.random.default_rng(seed)
    kinds, z, finite, y_before, missed, psi = differencing_case(rng, G, T, carried)
    kinds, gaps, _ = differenced_kinds(kinds, z, finite, y_before, missed, psi)
    params = np.stack([10.0 ** rng.uniform(-2, 4, G), 10.0 ** rng.uniform(-1, 2, G), psi], axis=1)
    var = params[:, 1] ** 2 / (1.0 - psi**2)
    P_start = np.zeros((2, 2, G))
    P_start[0, 0], P_start[1, 1] = var, 1e6 * var / AXIS.tau**2
    P_start[0, 1] = P_start[1, 0] = rng.uniform(-0.5, 0.5, G) * np.sqrt(P_start[0, 0] * P_start[1, 1])
    return kinds, cmn_tables(AXIS, params, gaps), P_start


def assert_same_gains(kinds: np.ndarray, tables: kc.StepTables, P_start: np.ndarray) -> None:
    coef, steady, P_end = kk.gain_recursion(kinds, tables, P_start)
    coef_ref, steady_ref, P_ref = kc.gain_recursion(kinds, tables, P_start)
    assert steady == steady_ref
    assert coef.shape == coef_ref.shape and P_end.shape == P_ref.shape
    assert_close(coef, coef_ref)
    assert_close(P_end, P_ref)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), C=st.integers(1, 6), T=st.integers(1, 100), prior=st.sampled_from(["no", "yes", "some"]),
       carried=st.booleans())
def test_frame_kinds_kernel_equals_reference(seed: int, C: int, T: int, prior: str, carried: bool) -> None:
    rng = np.random.default_rng(seed)
    finite = gappy_mask(rng, C, T)
    with_prior = {"no": False, "yes": True, "some": rng.random(C) < 0.5}[prior]
    measured = rng.random(C) < 0.5 if carried else None
    got = kk.frame_kinds(finite, with_prior, measured)
    assert got.dtype == np.int8
    np.testing.assert_array_equal(got, kc.frame_kinds_numpy(finite, with_prior, measured))


def assert_same_differences(kinds: np.ndarray, *inputs: np.ndarray) -> None:
    got = kk.differenced_kinds(kinds.copy(), *inputs)
    want = differenced_kinds(kinds.copy(), *inputs)
    assert got[0].dtype == want[0].dtype
    np.testing.assert_array_equal(got[0], want[0])  # kinds
    np.testing.assert_array_equal(got[1], want[1])  # gap lengths
    assert_close(got[2], want[2])  # measurements m_n


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), C=st.integers(1, 6), T=st.integers(1, 150), carried=st.booleans())
def test_differencing_kernel_equals_reference(seed: int, C: int, T: int, carried: bool) -> None:
    assert_same_differences(*differencing_case(np.random.default_rng(seed), C, T, carried))


def test_differencing_kernel_beyond_123_gap_lengths() -> None:
    """Gaps of 1 … 130 frames in one call: int32 kinds, as the reference makes them."""
    rng = np.random.default_rng(5)
    finite = np.concatenate([np.r_[True, np.zeros(g, bool)] for g in rng.permutation(np.arange(1, 131))] + [[True]])
    finite = np.stack([finite, ~runs_missing(rng, finite.size)])
    z = np.where(finite, rng.normal(100.0, 20.0, finite.shape), np.nan)
    kinds = kc.frame_kinds(finite, prior=np.array([False, True]), measured=np.array([False, True]))
    y_before, missed, psi = np.array([np.nan, 90.0]), np.array([0, 2]), np.array([0.3, 0.9])
    assert_same_differences(kinds, z, finite, y_before, missed, psi)
    assert differenced_kinds(kinds, z, finite, y_before, missed, psi)[0].dtype == np.int32


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), G=st.integers(1, 5), T=st.integers(1, 150), carried=st.booleans())
def test_gain_kernel_equals_reference_on_kf_cmn_kinds(seed: int, G: int, T: int, carried: bool) -> None:
    assert_same_gains(*cmn_case(seed, G, T, carried))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), G=st.integers(1, 4), T=st.integers(1, 60), n_kinds=st.integers(5, 9))
def test_gain_kernel_equals_reference_on_random_tables(seed: int, G: int, T: int, n_kinds: int) -> None:
    """Any kind at any frame (WAIT/INIT resets between updates), random transitions, noises, cross-covariances."""
    rng = np.random.default_rng(seed)
    kinds = rng.integers(0, n_kinds, (G, T)).astype(np.int8)
    A = np.eye(2)[None, :, :, None] + rng.uniform(-0.3, 0.3, (n_kinds, 2, 2, G))
    B = rng.normal(size=(n_kinds, 2, 2, G))
    Q = np.einsum("kijg,kljg->kilg", B, B)
    M = rng.normal(size=(n_kinds, 2, G)) * (rng.random((n_kinds, 1, 1)) < 0.5)  # some kinds time-correlated
    tables = kc.StepTables(A=A, Q=Q, Lam=rng.normal(size=(n_kinds, 2, G)), D=rng.normal(size=(n_kinds, 2, G)),
                           R=10.0 + rng.random((n_kinds, G)) * 10.0, M=M)
    root = rng.normal(size=(2, 2, G))
    assert_same_gains(kinds, tables, np.einsum("ijg,kjg->ikg", root, root))


@pytest.mark.parametrize("G", [1, 3])
@pytest.mark.parametrize("kind", [kc.UPDATE_Y, kc.UPDATE_Z])
def test_gain_kernel_stops_at_the_references_steady_frame(G: int, kind: int) -> None:
    """Rows settling at different frames (39 … 151), the last after a late run of missing frames: the kernel stops
    where the reference stops."""
    params = np.array([[50.0, 4.0, 0.0], [1000.0, 4.0, 0.0], [50.0, 0.5, 0.0]])[:G]
    tables = cmn_tables(AXIS, params, np.zeros(1, np.int64))
    P_start = np.zeros((2, 2, G))
    P_start[0, 0], P_start[1, 1] = params[:, 1] ** 2, 1e6 * params[:, 1] ** 2 / AXIS.tau**2
    kinds = np.full((G, 400), kind, np.int8)
    kinds[:, 0] = kc.INIT
    kinds[-1, 200:230] = kc.PREDICT
    assert 230 <= kc.gain_recursion(kinds, tables, P_start)[1] < 400
    assert_same_gains(kinds, tables, P_start)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), G=st.sampled_from([1, 2, 3, 64, 65]), tau=st.sampled_from([1.0, 0.05, 1 / 30]),
       gaps=st.booleans())
def test_cmn_tables_kernel_equals_reference(seed: int, G: int, tau: float, gaps: bool) -> None:
    """KF-CMN's step tables from the kernel are the numpy reference's (one row, whose three-operand einsum sums in
    another order, and several; ψ = 0 rows, σ over 26 decades, gap kinds filled in by numpy). The kernel follows
    numpy 2.4's summation order and is bit for bit equal there; the test allows 1e-14 relative so that another
    numpy's einsum order does not fail it."""
    rng = np.random.default_rng(seed)
    params = np.stack([10.0 ** rng.uniform(-13, 13, G), 10.0 ** rng.uniform(-13, 13, G),
                       np.where(rng.random(G) < 0.2, 0.0, rng.uniform(0.0, 0.99, G))], axis=1)
    lengths = np.array([0, 1, 7]) if gaps else np.zeros(1, np.int64)
    axis = filters.constant_velocity(tau).axis()
    kernel, reference = both(lambda: cmn_tables(axis, params, lengths))
    for name in ("A", "Q", "Lam", "D", "R", "M"):
        got, want = getattr(kernel, name), getattr(reference, name)
        assert got.shape == want.shape == (len(lengths) + kc.UPDATE_Z, *want.shape[1:])
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=0, err_msg=name)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**16), G=st.sampled_from([1, 2, 64]), tau=st.sampled_from([1.0, 0.05]))
def test_kf_tables_kernel_equals_reference(seed: int, G: int, tau: float) -> None:
    """KF's step tables from the kernel are ``plain_tables``' with Q = σ_w² B Bᵀ, R = σ_v² (to 1e-14 relative; bit for
    bit with numpy 2.4)."""
    rng = np.random.default_rng(seed)
    params = 10.0 ** rng.uniform(-13, 13, (G, 2))
    axis = filters.constant_velocity(tau).axis()
    want = kc.plain_tables(axis.F, (axis.B @ axis.B.T)[:, :, None] * params[:, 0] ** 2, params[:, 1] ** 2, axis.H[0])
    got = kk.kf_tables(params, *axis_matrices(axis)[:3], kc.UPDATE_Z)
    for name, table in zip(("A", "Q", "Lam", "D", "R", "M"), got, strict=True):
        assert table.shape == getattr(want, name).shape
        np.testing.assert_allclose(table, getattr(want, name), rtol=1e-14, atol=0, err_msg=name)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), G=st.integers(1, 12), T=st.integers(1, 80), C=st.integers(1, 30),
       steady=st.integers(0, 90))
def test_affine_kernel_equals_reference(seed: int, G: int, T: int, C: int, steady: int) -> None:
    """Both reference paths (blocks of frames for G <= BLOCK_ROWS, frame by frame beyond); measurements 0 at gaps."""
    rng = np.random.default_rng(seed)
    coef = np.concatenate([rng.uniform(-0.6, 0.6, (T, 4, G)) + np.array([0.3, 0, 0, 0.3])[:, None],
                           rng.normal(size=(T, 2, G))], axis=1)
    coef[rng.random(T) < 0.1] = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0])[:, None]  # INIT frames
    coef[steady:] = coef[min(steady, T - 1)]  # the contract: constant from the steady frame on
    m = np.where(rng.random((C, T)) < 0.5, 0.0, rng.normal(100.0, 30.0, (C, T)))
    row_of_channel = rng.integers(0, G, C)
    x_start = rng.normal(size=(C, 2))
    assert_close(kk.apply_affine(coef, steady, row_of_channel, m, x_start),
                 kc.apply_affine(coef, steady, row_of_channel, m, x_start))


def run_both(name: str, y: np.ndarray, params: dict, pieces: int) -> tuple[np.ndarray, np.ndarray]:
    """States of ``name`` on ``y`` (B, T, M) with the kernels on and off, run whole or as ``pieces`` carried runs."""
    f = filters.make(name, filters.constant_velocity(1 / 30, ndim=y.shape[2]), **params)
    out = []
    for compiled in (True, False):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(jit, "ENABLED", compiled)
            carry, parts = None, []
            for piece in np.array_split(y, pieces, axis=1):
                states, carry = f.run_from(piece, carry)
                parts.append(states)
            out.append(np.concatenate(parts, axis=1))
    return out[0], out[1]


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**16), name=st.sampled_from(["kf", "kf_cmn", "ukf"]), T=st.integers(1, 200),
       pieces=st.integers(1, 3))
def test_filters_equal_with_kernels_on_and_off(seed: int, name: str, T: int, pieces: int) -> None:
    """Box tracks with 40–60 % of their frames missing in runs, per-track parameters, whole or carried runs."""
    rng = np.random.default_rng(seed)
    B = 4
    y = 200.0 + np.cumsum(rng.normal(0.0, 2.0, (B, T, 4)), axis=1)
    y[gappy_mask(rng, B, T)[:, :, None].repeat(4, axis=2) == 0] = np.nan
    y[0, rng.random(T) < 0.2, 1] = np.nan  # one coordinate missing on its own
    params = {"sigma_w": 10.0 ** rng.uniform(0, 3, B), "sigma_v": 10.0 ** rng.uniform(-1, 1, B)}
    if name == "kf_cmn":
        params["psi"] = rng.uniform(0.0, 0.95, B)
    with_kernels, references = run_both(name, y, params, min(pieces, T))
    assert_close(with_kernels, references)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), C=st.integers(1, 6), T=st.integers(1, 60), k=st.integers(1, 2),
       n_bad=st.integers(0, 3))
def test_nonfinite_check_kernel_equals_reference(seed: int, C: int, T: int, k: int, n_bad: int) -> None:
    """The filters' check of their estimates (base.Filter._check_finite): non-finite entries before a channel's
    first finite measurement are allowed (WAIT frames), the first one after it is found, on full and sliced arrays."""
    rng = np.random.default_rng(seed)
    z = np.where(gappy_mask(rng, C, T), 1.0, np.nan)
    estimates = rng.normal(size=(C, T, 2))
    estimates[np.isnan(z)] = np.nan  # NaN at missing frames (WAIT ones among them)
    for _ in range(n_bad):
        estimates[rng.integers(C), rng.integers(T), rng.integers(2)] = rng.choice([np.nan, np.inf, -np.inf])
    want = first_nonfinite_numpy(estimates[..., :k], z)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(jit, "ENABLED", True)
        assert first_nonfinite(estimates[..., :k], z) == want
