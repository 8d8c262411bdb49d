"""The compiled scoring (``bboxtune.envs.episodes.scoring_kernels``) and finiteness check (``bboxtune.filters.finite_check``)
against their numpy references, and the batched vec env with the kernels on and off."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from bboxtune import filters
from bboxtune.agents.training.runs import make_vec
from bboxtune.envs.episodes import scoring
from bboxtune.filters import finite_check, jit

# boxes (cx, cy, w, h): integer and half-pixel values hit IoU / centre-error ties with the thresholds exactly (equal
# boxes: IoU 1; centre offsets (12, 16): 20 px); zero and negative sizes are degenerate boxes (zero area)
coordinate = st.one_of(st.integers(-30, 30).map(float), st.integers(-60, 60).map(lambda v: v / 2),
                       st.floats(-40.0, 40.0, allow_nan=False))
size = st.one_of(st.integers(-2, 20).map(float), st.floats(0.0, 30.0, allow_nan=False), st.just(0.0))


@st.composite
def boxes(draw: st.DrawFn, shape: tuple[int, ...], missing: float) -> np.ndarray:
    """Boxes of ``shape`` (..., 4) with rows NaN (or one coordinate NaN / ±inf) at rate about ``missing``."""
    n = int(np.prod(shape[:-1]))
    rows = draw(st.lists(st.tuples(coordinate, coordinate, size, size), min_size=n, max_size=n))
    out = np.array(rows, dtype=float).reshape(shape)
    flat = out.reshape(-1, 4)
    for i in range(n):
        kind = draw(st.sampled_from(["ok"] * max(1, round((1 - missing) * 8)) + ["nan", "one", "inf"]))
        if kind == "nan":
            flat[i] = np.nan
        elif kind in ("one", "inf"):
            flat[i, draw(st.integers(0, 3))] = np.nan if kind == "one" else draw(st.sampled_from([np.inf, -np.inf]))
    return out


def near(est: np.ndarray, truth: np.ndarray, draw: st.DrawFn) -> np.ndarray:
    """Some estimates equal to the truth or at a 20 px centre offset (the thresholds' ties)."""
    out = est.copy()
    for idx in np.ndindex(out.shape[:-1]):
        pick = draw(st.integers(0, 5))
        g = truth[idx[-1]] if truth.ndim == 2 else truth[idx]
        if pick == 0:
            out[idx] = g
        elif pick == 1:
            out[idx] = g + np.array([12.0, 16.0, 0.0, 0.0])
    return out


def assert_scores_equal(got: dict[str, np.ndarray], want: dict[str, np.ndarray]) -> None:
    assert set(got) == set(want) == set(scoring.SCORE_KEYS)
    for k in scoring.SCORE_KEYS:
        assert got[k].shape == want[k].shape, k
        np.testing.assert_allclose(got[k], want[k], rtol=1e-9, atol=1e-12, err_msg=k)  # NaN where the reference has NaN


@pytest.fixture(scope="module")
def kernels_on() -> Iterator[None]:
    """The kernels run in this module's tests (also under ``$BBOXTUNE_JIT=0``), which compare them with the references."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(jit, "ENABLED", True)
        yield


@settings(max_examples=40, deadline=None)
@given(data=st.data(), A=st.integers(1, 4), T=st.integers(1, 12), shared=st.booleans())
def test_score_estimates_kernel_equals_numpy(kernels_on: None, data: st.DataObject, A: int, T: int, shared: bool) -> None:
    truth = data.draw(boxes((T, 4) if shared else (A, T, 4), missing=0.2))
    est = near(data.draw(boxes((A, T, 4), missing=0.3)), truth, data.draw)
    with np.errstate(invalid="ignore"):  # ±inf coordinates (missing rows) in the reference's arithmetic
        want = scoring.score_estimates_numpy(est, truth)
    assert_scores_equal(scoring.score_estimates(est, truth), want)


@settings(max_examples=30, deadline=None)
@given(data=st.data(), lengths=st.lists(st.integers(1, 9), min_size=1, max_size=5))
def test_score_tracks_kernel_equals_numpy(kernels_on: None, data: st.DataObject, lengths: list[int]) -> None:
    truths = [data.draw(boxes((T, 4), missing=0.2)) for T in lengths]
    estimates = [near(data.draw(boxes((T, 4), missing=0.3)), g, data.draw) for T, g in zip(lengths, truths, strict=True)]
    estimates[0] = np.asfortranarray(estimates[0])  # any layout (the envs' truths are column-major views)
    with np.errstate(invalid="ignore"):
        want = scoring.score_tracks_numpy(estimates, truths)
    assert_scores_equal(scoring.score_tracks(estimates, truths), want)


@pytest.mark.parametrize("T", [1, 7, 8, 129, 500, 1037, 4099])
def test_kernel_scores_equal_numpy_bit_for_bit(kernels_on: None, T: int) -> None:
    """The sums over frames follow numpy's pairwise summation: the scores are the reference's to the last bit (old
    configurations' episodes are pinned by hash: tests/envs/test_mix_mot.py)."""
    rng = np.random.default_rng(T)
    truth = rng.uniform(20.0, 200.0, (T, 4))
    est = truth + rng.normal(0.0, 8.0, (6, T, 4))
    truth[rng.random(T) < 0.05] = np.nan
    est[rng.random((6, T)) < 0.1] = np.nan
    full = np.nan_to_num(est, nan=1.0)
    for scored in (est, full):  # with and without missing estimates
        pairs = [(scoring.score_estimates(scored, truth), scoring.score_estimates_numpy(scored, truth)),
                 (scoring.score_tracks(list(scored), [truth] * 6), scoring.score_tracks_numpy(list(scored), [truth] * 6))]
        for got, want in pairs:
            for k in scoring.SCORE_KEYS:
                np.testing.assert_array_equal(got[k], want[k], err_msg=k)


@pytest.mark.parametrize("shape", [(0, 5, 4), (3, 0, 4)])
def test_empty_batches(kernels_on: None, shape: tuple[int, int, int]) -> None:
    est, truth = np.zeros(shape), np.zeros(shape[1:])
    with np.errstate(invalid="ignore", divide="ignore"):
        assert_scores_equal(scoring.score_estimates(est, truth), scoring.score_estimates_numpy(est, truth))
    assert all(len(v) == 0 for v in scoring.score_tracks([], []).values())


def test_all_missing_and_mismatched_shapes(kernels_on: None) -> None:
    est, truth = np.full((2, 3, 4), np.nan), np.ones((3, 4))
    got = scoring.score_estimates(est, truth)
    assert np.isnan(got["rmse"]).all() and np.isnan(got["iou_precision"]).all() and (got["success_auc"] == 0).all()
    with pytest.raises(ValueError, match="allowed"):
        scoring.score_estimates(est, np.ones((4, 4)))
    with pytest.raises(ValueError, match="one of each track's length"):
        scoring.score_tracks([np.ones((2, 4))], [np.ones((3, 4))])


@settings(max_examples=50, deadline=None)
@given(data=st.data(), C=st.integers(1, 6), T=st.integers(1, 10), k=st.sampled_from([1, 2]), transposed=st.booleans())
def test_finite_checks_kernel_equal_numpy(data: st.DataObject, C: int, T: int, k: int, transposed: bool) -> None:
    values = st.sampled_from([0.0, 1.5, -2.0, np.nan, np.inf, -np.inf])
    z = data.draw(hnp.arrays(float, (C, T), elements=st.sampled_from([1.0, np.nan, np.nan])))
    axes = data.draw(hnp.arrays(float, (C, T, k), elements=st.one_of(st.just(1.0), values)))
    if transposed:  # the FIR family returns (C, 2, T) arrays seen as (C, T, 2)
        axes = np.ascontiguousarray(axes.transpose(0, 2, 1)).transpose(0, 2, 1)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(jit, "ENABLED", True)
        assert finite_check.first_nonfinite(axes, z) == finite_check.first_nonfinite_numpy(axes, z)
        M = data.draw(st.sampled_from([m for m in (1, 2, 3) if C % m == 0]))
        got, want = np.full((C // M, T, M), -7.0), np.full((C // M, T, M), -7.0)
        assert finite_check.write_positions(axes, z, got) == finite_check.write_positions_numpy(axes, z, want)
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("enabled", [True, False])
def test_filter_reports_a_nonfinite_estimate(monkeypatch: pytest.MonkeyPatch, enabled: bool) -> None:
    monkeypatch.setattr(jit, "ENABLED", enabled)
    flt = filters.make("kf", filters.constant_velocity(1.0, ndim=2))
    run_axes = flt._run_axes

    def broken(z: np.ndarray, params: dict[str, Any], positions_only: bool = False) -> np.ndarray:
        out = run_axes(z, params, positions_only).copy()
        out[3, 4:, 0] = np.nan  # track 1, coordinate 1 from frame 4 on
        return out

    monkeypatch.setattr(flt, "_run_axes", broken)
    y = np.ones((2, 6, 2))
    with pytest.raises(FloatingPointError, match="track 1, coordinate 1, frame 4"):
        flt.positions(y)
    y[1, :5, 1] = np.nan  # no measurement before frame 5 in that channel: frame 5 is the first checked
    with pytest.raises(FloatingPointError, match="track 1, coordinate 1, frame 5"):
        flt.run(y)


def vec_steps(backend: str) -> tuple[list[np.ndarray], list[list[dict[str, Any]]]]:
    venv = make_vec("bboxtune/FilterTune-v0", {"backend": backend, "track_length": 60}, split="train", n_envs=5, seed=3,
                    vec_env="batched")
    arrays: list[np.ndarray] = [venv.reset()]
    infos = []
    actions = np.random.default_rng(0).uniform(-1, 1, (2, 5, venv.action_space.shape[0])).astype(np.float32)
    for a in actions:
        obs, rewards, dones, info = venv.step(a)
        arrays += [obs, rewards, dones]
        infos.append([{k: v for k, v in i.items() if k != "episode"} for i in info])  # "episode" holds wall time
    return arrays, infos


def assert_nested_close(a: Any, b: Any) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            assert_nested_close(a[k], b[k])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_nested_close(x, y)
    elif isinstance(a, (float, np.ndarray)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    else:
        assert a == b


@pytest.mark.parametrize("backend", ["ufir_cmn", "kf_cmn"])
def test_vec_env_same_with_kernels_on_and_off(monkeypatch: pytest.MonkeyPatch, backend: str) -> None:
    monkeypatch.setattr(jit, "ENABLED", False)
    reference = vec_steps(backend)
    monkeypatch.setattr(jit, "ENABLED", True)
    assert_nested_close(vec_steps(backend), reference)
