"""FIRFilter machinery (filters/fir_core.py): the generic start-up / NaN-window / fallback paths against the
literal iterative algorithm, the UFIR family's vectorised overrides against the generic paths, the kernel
correlation, the gain cache and the shared parameter checks."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.filters.fir_core import GAINS, FIRFilter, GainCache, check_fir_params, correlate
from bboxtune.filters.ufir import UFIR, ufir_iterative
from bboxtune.filters.ufir_cmn import UFIRCMN

TAU = 0.05
MODEL1 = filters.constant_velocity(TAU, ndim=1)
AXIS = MODEL1.axis()


class GenericUFIR(UFIR):
    """UFIR through the base class's generic paths only (per-point / per-mask gains, default window_gains)."""

    _run_frames = FIRFilter._run_frames  # not UFIR's compiled scan
    _startup = FIRFilter._startup
    _masked = FIRFilter._masked
    window_gains = FIRFilter.window_gains

    def window_gain(self, valid, params):
        return UFIR.window_gains(self, np.asarray(valid)[None], {k: np.array([v]) for k, v in params.items()})[0]


class GenericUFIRCMN(UFIRCMN):
    _run_frames = FIRFilter._run_frames
    _startup = FIRFilter._startup
    _masked = FIRFilter._masked


def noisy_tracks(B: int, T: int, seed: int, missing: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = 200.0 + np.cumsum(20.0 + np.cumsum(rng.normal(0, 2.5, (B, T)), axis=1), axis=1) * TAU
    y += rng.normal(0, 4.0, (B, T))
    y[rng.uniform(size=(B, T)) < missing] = np.nan
    y[:, 15:19] = np.nan  # a run every track shares
    return y


def assert_close(fast: np.ndarray, ref: np.ndarray, rtol: float = 1e-8) -> None:
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(ref))
    scale = np.maximum(np.nanmax(np.abs(ref), axis=(0, 1)), 1.0)
    worst = np.nanmax(np.abs(fast - ref), axis=(0, 1), initial=0.0) / scale
    assert np.all(worst < rtol), f"relative difference {worst} >= {rtol}"


def test_generic_paths_equal_the_iterative_algorithm() -> None:
    y = noisy_tracks(4, 70, seed=0, missing=0.1)
    horizons = np.array([2, 5, 5, 30])
    out = GenericUFIR(MODEL1, horizon=horizons).run(y[:, :, None])
    ref = np.stack([ufir_iterative(y[b], AXIS.F, AXIS.H, int(N)) for b, N in enumerate(horizons)])
    assert_close(out, ref)


@pytest.mark.parametrize("missing", [0.0, 0.15])
def test_ufir_family_overrides_equal_the_generic_paths(missing: float) -> None:
    y = noisy_tracks(6, 80, seed=1, missing=missing)[:, :, None]
    horizons = np.array([2, 3, 9, 9, 40, 120])
    psi = np.array([0.0, 0.5, 0.2, 0.9, 0.7, 0.6])
    assert_close(UFIR(MODEL1, horizon=horizons).run(y), GenericUFIR(MODEL1, horizon=horizons).run(y))
    assert_close(UFIRCMN(MODEL1, horizon=horizons, psi=psi).run(y),
                 GenericUFIRCMN(MODEL1, horizon=horizons, psi=psi).run(y), rtol=1e-7)


def test_masked_gains_are_cached_and_reused() -> None:
    GAINS.clear()
    y = noisy_tracks(2, 50, seed=2, missing=0.1)[:, :, None]
    f = GenericUFIR(MODEL1, horizon=7)
    first = f.run(y)
    n_cached = len(GAINS._store)
    assert n_cached > 1 and GAINS.nbytes > 0
    np.testing.assert_array_equal(f.run(y), first)
    assert len(GAINS._store) == n_cached  # second run: all hits
    gain = next(iter(GAINS._store.values()))
    assert not gain.flags.writeable


def test_fallback_before_and_during_unobservable_stretches() -> None:
    y = np.array([np.nan, np.nan, 4.0, np.nan, np.nan, np.nan, 7.0, 8.0])
    out = filters.make("ufir", MODEL1, horizon=3).run(y[:, None])
    assert np.all(np.isnan(out[:2]))  # nothing seen yet
    np.testing.assert_allclose(out[2:6], [[4.0, 0.0]] * 4)  # one sample in the window: hold it, velocity 0
    np.testing.assert_allclose(out[6], [7.0, 0.0])
    np.testing.assert_allclose(out[7], [8.0, 1.0 / TAU])


@pytest.mark.parametrize("wrap", [False, True])
@pytest.mark.parametrize("L", [1, 3, 24, 300])
def test_correlate_matches_sliding_products(L: int, wrap: bool) -> None:
    rng = np.random.default_rng(L)
    y0 = rng.normal(size=(5, 120)) + 1e3
    W = rng.normal(size=(2, 2, L))
    W[1, :, : L // 2] = 0.0  # group 1: a shorter kernel, right-aligned
    L_g = [L, L - L // 2]
    group = np.array([0, 1, 1, 0, 1])
    out = correlate(y0, W, group, wrap=wrap)
    padded = np.concatenate([np.zeros((5, L - 1)), y0], axis=1)
    for c in range(5):
        first = L_g[group[c]] - 1 if wrap else 0  # wrap: exact from the first full window on
        for n in sorted({0, 1, min(L - 1, 119), 119}):
            if n >= first:
                np.testing.assert_allclose(out[c, n], W[group[c]] @ padded[c, n:n + L], rtol=1e-11, atol=1e-9)


def test_gain_cache_evicts_least_recently_used_by_bytes() -> None:
    cache = GainCache(max_bytes=3 * 80)
    for k in range(3):
        cache.put(("g", k), np.zeros(10))
    assert cache.get(("g", 0)) is not None  # 0 becomes most recent
    cache.put(("g", 3), np.zeros(10))
    assert cache.get(("g", 1)) is None and cache.get(("g", 0)) is not None and cache.nbytes == 240


def test_check_fir_params_rule_and_errors() -> None:
    out = check_fir_params({"sigma_w": np.array([50.0, 5.0]), "sigma_v": 4.0, "horizon": None}, MODEL1)
    np.testing.assert_array_equal(out["horizon"], filters.rule_horizon(4.0, np.array([50.0, 5.0]), TAU, 2))
    for bad, name in [({"horizon": 1}, "horizon"), ({"sigma_w": -1.0}, "sigma_w"), ({"sigma_v": np.inf}, "sigma_v"),
                      ({"sigma_w": np.ones(2), "sigma_v": np.ones(3)}, "lengths")]:
        with pytest.raises(ValueError, match=name):
            check_fir_params({"sigma_w": 1.0, "sigma_v": 1.0, "horizon": None, **bad}, MODEL1)


@pytest.mark.parametrize("name", filters.NAMES)
def test_positions_equal_the_position_columns_of_run(name: str) -> None:
    model = filters.constant_velocity(TAU, ndim=2)
    y = np.stack([noisy_tracks(3, 80, seed=s, missing=0.05) for s in (4, 5)], axis=-1)  # (3, 80, 2)
    f = filters.make(name, model, **({"horizon": 12} if "horizon" in filters.filter_class(name).DEFAULTS else {}))
    states = f.run(y)
    np.testing.assert_allclose(f.positions(y), states[..., :2], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(f.positions(y[1]), states[1, :, :2], rtol=1e-12, atol=1e-9)


def test_params_in_frames_takes_one_interval_per_track() -> None:
    params = {"sigma_w": np.array([2.0, 3.0]), "horizon": np.array([5, 6])}
    out = UFIR.params_in_frames(params, np.array([0.1, 0.5]))
    np.testing.assert_allclose(out["sigma_w"], [0.02, 0.75])
    assert out["horizon"] is params["horizon"]
    OFIR = filters.filter_class("ofir")
    with pytest.raises(ValueError, match="P0 is one matrix"):
        OFIR.params_in_frames({"sigma_w": 1.0, "P0": np.eye(2)}, np.array([0.1, 0.2]))
