"""bboxtune.filters.batch: candidates and per-track parameter sets in few calls, frame units handled in one place."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters

PARAMS = {"psi": np.array([0.0, 0.5, 0.9]), "horizon": np.array([4, 20, 60]), "sigma_w": np.array([1.0, 10.0, 100.0]),
          "sigma_v": np.array([0.5, 2.0, 8.0])}


def _params(name: str, rows: slice | np.ndarray = slice(None)) -> dict[str, np.ndarray]:
    accepted = filters.filter_class(name).DEFAULTS
    return {k: v[rows] for k, v in PARAMS.items() if k in accepted}


def _y(T: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = 100 + np.cumsum(rng.normal(size=(T, 4)), axis=0) + rng.normal(size=(T, 4))
    y[T // 3: T // 3 + 3] = np.nan
    return y


@pytest.mark.parametrize("name", filters.NAMES)
def test_candidates_equal_separate_runs_at_the_track_s_interval(name: str) -> None:
    y, tau = _y(90, 0), 0.04
    est = filters.candidate_positions(name, y, tau, _params(name))
    assert est.shape == (3, 90, 4)
    for i in range(3):
        alone = filters.make(name, filters.constant_velocity(tau, ndim=4), **_params(name, slice(i, i + 1))).positions(y[None])
        np.testing.assert_allclose(est[i], alone[0], rtol=1e-9, atol=1e-8)


@pytest.mark.parametrize("name", filters.NAMES)
def test_tracks_of_different_lengths_and_intervals_equal_each_track_alone(name: str) -> None:
    ys, taus = [_y(90, 1), _y(60, 2), _y(90, 3)], [0.04, 0.1, 1 / 30]
    est = filters.track_positions(name, ys, taus, _params(name))
    for i in range(3):
        alone = filters.candidate_positions(name, ys[i], taus[i], _params(name, slice(i, i + 1)))[0]
        np.testing.assert_allclose(est[i], alone, rtol=1e-12, atol=1e-9)



@pytest.mark.parametrize("name", filters.NAMES)
def test_one_track_equals_track_positions_bit_for_bit_from_its_cached_filter(name: str) -> None:
    """Each parameter set gets its own filter: repeated and interleaved calls give each set's own estimates."""
    y, tau = _y(60, 4), 1 / 30
    expected = [filters.track_positions(name, [y], [tau], _params(name, slice(i, i + 1)))[0] for i in range(3)]
    for _ in range(2):
        for i in range(3):
            assert np.array_equal(filters.one_track_positions(name, y, tau, _params(name, slice(i, i + 1))),
                                  expected[i], equal_nan=True)
    if _params(name):  # a back end with parameters: the sets differ
        assert not np.array_equal(expected[0], expected[2], equal_nan=True)
