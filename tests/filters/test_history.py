"""The FIR family's run_from (bboxtune.filters.history): continuing from the measurement history equals one run over the
whole track, with new parameters applying from the first new frame; candidates continue from one history."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.filters.history import History

FIR = ("ufir", "ufir_cmn", "ofir", "oufir", "fir")
TAU = 0.05


def _track(T: int = 160, B: int = 3, seed: int = 0, gaps: bool = False) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = np.cumsum(np.cumsum(rng.normal(size=(B, T, 4)), axis=1), axis=1) * 0.05 + rng.normal(size=(B, T, 4))
    if gaps:  # gaps shorter than every horizon used below
        for b in range(B):
            for start in rng.choice(T - 8, 4, replace=False):
                y[b, start:start + rng.integers(1, 6)] = np.nan
    return y


@pytest.mark.parametrize("gaps", [False, True])
@pytest.mark.parametrize("name", FIR)
def test_continued_runs_equal_one_run_over_the_whole_track(name: str, gaps: bool) -> None:
    y = _track(gaps=gaps)
    flt = filters.make(name, filters.constant_velocity(TAU, ndim=4), horizon=np.array([8, 20, 35]))
    whole = flt.run(y)
    pieces, history = [], None
    for lo, hi in ((0, 5), (5, 50), (50, 51), (51, 160)):  # a piece shorter than the horizon, one frame, ...
        states, history = flt.run_from(y[:, lo:hi], history)
        pieces.append(states)
    np.testing.assert_allclose(np.concatenate(pieces, axis=1), whole, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(history.y, y)
    positions, _ = flt.positions_from(y[:, 100:], History(y[:, :100]))
    np.testing.assert_allclose(positions, whole[:, 100:, :4], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", ["ufir_cmn", "oufir"])
def test_new_parameters_apply_from_the_first_new_frame(name: str) -> None:
    y = _track(B=1)[0]
    model = filters.constant_velocity(TAU, ndim=4)
    _, history = filters.make(name, model, horizon=10).run_from(y[:80])
    after, _ = filters.make(name, model, horizon=40).run_from(y[80:], history)
    np.testing.assert_allclose(after, filters.make(name, model, horizon=40).run(y)[80:], rtol=1e-9, atol=1e-9)


def test_candidates_continue_from_one_history() -> None:
    y = _track(B=1)[0]
    model = filters.constant_velocity(TAU, ndim=4)
    _, history = filters.make("ufir", model, horizon=12).run_from(y[:60])
    horizons = np.array([4, 12, 50])
    states, after = filters.make("ufir", model, horizon=horizons).run_from(np.broadcast_to(y[60:], (3, 100, 4)),
                                                                           history.repeat(3))
    for i, h in enumerate(horizons):
        np.testing.assert_allclose(states[i], filters.make("ufir", model, horizon=int(h)).run(y)[60:], rtol=1e-9,
                                   atol=1e-9)
    assert after.y.shape == (3, 160, 4) and not after.y.flags.writeable


def test_a_run_continued_inside_a_gap_longer_than_the_horizon_has_no_estimate_until_the_next_measurement() -> None:
    """Documented limit (bboxtune.filters.history): after a gap longer than the horizon one run holds its last estimate;
    a run continued inside the gap reaches back only max(N) + 1 frames, finds no measurement there and has no
    estimate (NaN) until the gap ends — from then on both are equal."""
    y = _track(B=1)[0]
    y[60:90] = np.nan  # 30 missing frames > the horizon 8
    flt = filters.make("ufir", filters.constant_velocity(TAU, ndim=4), horizon=8)
    whole = flt.run(y)
    states, _ = flt.run_from(y[80:], History(y[None, :80]))
    np.testing.assert_allclose(states[20:], whole[100:], rtol=1e-9, atol=1e-9)  # after the gap: equal again
    assert np.isnan(states[:10]).all() and np.isfinite(whole[80:90]).all()


def test_history_checks_its_shapes() -> None:
    model = filters.constant_velocity(TAU, ndim=4)
    flt = filters.make("ufir", model, horizon=10)
    with pytest.raises(ValueError, match="carry holds 2 track"):
        flt.run_from(np.zeros((20, 4)), History(np.zeros((2, 5, 4))))
    with pytest.raises(ValueError, match="allowed \\(B, H, M\\)"):
        History(np.zeros((5, 4)))
    with pytest.raises(ValueError, match="one-track history"):
        History(np.zeros((2, 5, 4))).repeat(3)
    with pytest.raises(ValueError, match="n=0"):
        History(np.zeros((1, 5, 4))).repeat(0)
    with pytest.raises(ValueError, match="no camera states"):
        flt.run_from(np.zeros((20, 4)), None, np.zeros((20, 2)))


def test_a_history_never_follows_later_changes_of_the_caller_s_array() -> None:
    y = np.zeros((1, 5, 4))
    history = History(y)
    y[0, 0, 0] = 1.0
    assert history.y[0, 0, 0] == 0.0 and not history.y.flags.writeable
    assert np.shares_memory(history.repeat(3).y, history.y)  # candidates share one history, no copies
