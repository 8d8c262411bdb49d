"""OnlineBoxKF (the trackers' filters one frame at a time over a changing set of tracks) equals the batch recursion."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters
from bboxtune.filters.box_online import OnlineBoxKF, _table_variance, track_params
from bboxtune.filters.box_state import HeightVariance

MODEL = filters.constant_velocity(1 / 25, ndim=4)


def _tracks(rng: np.random.Generator, n: int, T: int) -> np.ndarray:
    """(n, T, 4) cx, cy, w, h boxes with missing frames and leading NaN (tracks start at different frames)."""
    steps = rng.normal(0, [2.0, 1.5, 0.4, 0.6], (n, T, 4)).cumsum(axis=1)
    y = steps + np.array([300.0, 200.0, 40.0, 90.0])
    y[rng.random((n, T)) < 0.25] = np.nan
    for i, start in enumerate(rng.integers(0, T // 2, n)):
        y[i, :start] = np.nan
        y[i, start] = np.array([300.0, 200.0, 40.0, 90.0]) + rng.normal(0, 3, 4)
    return y


@pytest.mark.parametrize("name", ["bytetrack_kf", "sort_kf"])
def test_frame_by_frame_with_births_equals_run(name: str) -> None:
    rng = np.random.default_rng(3)
    y = _tracks(rng, 12, 80)
    kf = filters.make(name, MODEL)
    online = OnlineBoxKF(kf)
    first = np.argmax(~np.isnan(y[..., 0]), axis=1)
    order: list[int] = []  # the track of each online column
    got = np.full(y.shape, np.nan)
    for t in range(y.shape[1]):
        if online.n:
            got[order, t] = online.update(y[order, t])
        born = [i for i in range(len(y)) if first[i] == t]
        if born:
            online.start(y[born, t])
            got[born, t] = y[born, t]
            order += born
    want = kf.positions(y)
    np.testing.assert_array_equal(got, want)  # the same operations in the same order: bit for bit


def test_prediction_ending_tracks_and_new_parameters() -> None:
    rng = np.random.default_rng(4)
    y = _tracks(rng, 6, 40)
    y[:, 0] = np.array([300.0, 200.0, 40.0, 90.0])  # every track starts at frame 0
    kf = filters.make("bytetrack_kf", MODEL)
    online = OnlineBoxKF(kf)
    online.start(y[:, 0])
    for t in range(1, 20):
        online.update(y[:, t])
    predicted = online.predict()
    est, carry = kf.run_from(y[:, :20])
    ahead, _ = kf.run_from(np.full((6, 1, 4), np.nan), carry)
    np.testing.assert_allclose(predicted, ahead[:, 0, :4], rtol=1e-12)
    online.keep(np.array([4, 1]))
    online.set_params(np.array([1]), {"std_weight_position": 0.2, "std_weight_velocity": 0.01})
    got = np.stack([online.update(y[[4, 1], t]) for t in range(20, 40)], axis=1)
    tuned = filters.make("bytetrack_kf", MODEL, std_weight_position=np.array([0.05, 0.2]),
                         std_weight_velocity=np.array([1 / 160, 0.01]))
    want, _ = tuned.run_from(y[[4, 1], 20:], carry.take(np.array([4, 1])))
    np.testing.assert_allclose(got, want[..., :4], rtol=1e-10, atol=1e-9)


def test_bad_input_is_refused() -> None:
    online = OnlineBoxKF(filters.make("sort_kf", MODEL))
    with pytest.raises(TypeError, match="kf is a KF"):
        OnlineBoxKF(filters.make("kf", MODEL))
    with pytest.raises(ValueError, match="allowed \\(k, 4\\)"):
        online.start(np.array([[1.0, 2.0, np.nan, 4.0]]))
    online.start(np.array([[10.0, 10.0, 5.0, 5.0]]))
    with pytest.raises(ValueError, match="allowed \\(1, 4\\)"):
        online.update(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="partly NaN"):
        online.update(np.array([[1.0, np.nan, 3.0, 4.0]]))
    with pytest.raises(TypeError, match="std_weight_position"):
        OnlineBoxKF(filters.make("bytetrack_kf", MODEL)).set_params(np.array([0]), {"std_weight_position": "1"})


def test_set_params_checks_only_the_given_parameters_as_make_does() -> None:
    """The parameters set equal track_params' (a filter built with them), and bad ones are refused by name."""
    kf = filters.make("bytetrack_kf", MODEL)
    online = OnlineBoxKF(kf)
    online.start(np.array([[10.0, 10.0, 5.0, 5.0], [40.0, 20.0, 6.0, 9.0], [70.0, 30.0, 8.0, 12.0]]))
    given = {"std_weight_position": np.array([0.2, 0.03]), "std_weight_velocity": 0.01}
    expected = track_params(kf, online.params, np.array([2, 0]), given)
    online.set_params(np.array([2, 0]), given)
    assert online.params.keys() == expected.keys()
    assert all(np.array_equal(online.params[k], expected[k]) for k in expected)
    assert online.params["std_weight_position"].tolist() == [0.03, kf.params["std_weight_position"], 0.2]
    with pytest.raises(ValueError, match="unknown parameter\\(s\\) \\['sigma_w'\\]"):
        online.set_params(np.array([0]), {"sigma_w": 1.0})
    with pytest.raises(ValueError, match="std_weight_velocity=.*out of range"):
        online.set_params(np.array([0]), {"std_weight_velocity": -1.0})


@pytest.mark.parametrize("name", ["bytetrack_kf", "sort_kf_scaled"])
def test_set_params_keeps_the_other_tracks_noise_and_equals_a_fresh_one(name: str) -> None:
    """After ``set_params`` only the re-tuned tracks' noise is rebuilt: the next frames are bit for bit those of an
    engine that rebuilds every track's noise, and they differ from the untuned engine's."""
    rng = np.random.default_rng(5)
    y = _tracks(rng, 8, 50)
    y[:, 0] = np.array([300.0, 200.0, 40.0, 90.0])
    engines = [OnlineBoxKF(filters.make(name, MODEL)) for _ in range(3)]
    for online in engines:
        online.start(y[:, 0])
        for t in range(1, 10):
            online.update(y[:, t])
    names = filters.make(name, MODEL).PER_TRACK[:2]
    rows = np.array([6, 1, 3])
    for online in engines[:2]:
        online.set_params(rows, {names[0]: np.array([0.3, 0.02, 0.1]), names[1]: 0.5})
    engines[1]._table = engines[1]._noise_table(engines[1]._values)  # every track's noise rebuilt
    engines[1]._changed()
    got = [np.stack([online.update(y[:, t]) for t in range(10, 50)]) for online in engines]
    np.testing.assert_array_equal(got[0], got[1])
    assert not np.allclose(got[0][:, rows], got[2][:, rows], equal_nan=True)
    others = np.setdiff1d(np.arange(8), rows)
    np.testing.assert_array_equal(got[0][:, others], got[2][:, others])


@pytest.mark.parametrize("name", ["bytetrack_kf", "sort_kf_scaled", "sort_kf"])
def test_noise_table_equals_a_full_rebuild(name: str) -> None:
    """The noise columns that start and keep move and set_params rebuilds per track equal, bit for bit, the noise
    built for all the live tracks at once from their parameters (as the batch recursion builds it)."""
    rng = np.random.default_rng(6)
    kf = filters.make(name, MODEL)
    online = OnlineBoxKF(kf)
    names = kf.PER_TRACK[:2]

    def boxes(k: int) -> np.ndarray:
        return np.array([300.0, 200.0, 40.0, 90.0]) + rng.normal(0, 5, (k, 4))

    for step in range(40):
        online.start(boxes(int(rng.integers(1, 4))))
        if names and step % 3 == 0:
            online.start(boxes(2), {names[0]: rng.uniform(0.01, 2.0, 2)})
        if names:
            rows = rng.choice(online.n, size=min(3, online.n), replace=False)
            online.set_params(rows, {names[0]: rng.uniform(0.01, 2.0, len(rows)), names[1]: rng.uniform(0.01, 2.0)})
        online.keep(rng.permutation(online.n)[:max(1, online.n - 1)])  # a track ends, the others are reordered
        measured = boxes(online.n)
        measured[rng.random(online.n) < 0.3] = np.nan
        online.update(measured)
    noise = kf._noise(online.params)
    assert online.n > 10
    for which, (pair, shape) in enumerate(zip((noise.start, noise.process, noise.measurement),
                                              ((2, 4), (2, 4), (4,)), strict=True)):
        want, got = HeightVariance(pair, (*shape, online.n)), _table_variance(online._table, which)
        np.testing.assert_array_equal(got.slope, want.slope)
        np.testing.assert_array_equal(got.offset, want.offset)
        assert (got.fixed is None) == (want.fixed is None) == (name == "bytetrack_kf")
        if want.fixed is not None:
            np.testing.assert_array_equal(got.fixed, want.fixed)


@pytest.mark.parametrize("name", ["bytetrack_kf", "sort_kf", "sort_kf_scaled"])
def test_update_after_predict_equals_update_alone(name: str) -> None:
    """An update right after predict() starts from its predicted state: bit for bit the update that predicts itself,
    also when tracks end, start or are re-tuned between the two calls."""
    rng = np.random.default_rng(8)
    y = _tracks(rng, 10, 60)
    kf = filters.make(name, MODEL)
    engines = [OnlineBoxKF(kf) for _ in range(2)]  # engines[0] predicts before every update
    cols = list(range(6))  # the track of each engine column
    first = np.array([300.0, 200.0, 40.0, 90.0]) + rng.normal(0, 5, (6, 4))
    for online in engines:
        online.start(first)
    for t in range(1, 60):
        engines[0].predict()
        if t % 7 == 3:  # a track ends, the others are reordered, another starts
            kept = rng.permutation(len(cols))[1:]
            born = np.array([[300.0, 200.0, 40.0, 90.0]]) + rng.normal(0, 5, (1, 4))
            for online in engines:
                online.keep(kept)
                online.start(born)
            cols = [cols[i] for i in kept] + [next(i for i in range(10) if i not in cols)]
        elif kf.PER_TRACK and t % 5 == 0:
            for online in engines:
                online.set_params(np.array([1, 3]), {kf.PER_TRACK[0]: 0.5 + t / 100})
        got, want = (online.update(y[cols, t]) for online in engines)
        np.testing.assert_array_equal(got, want)
