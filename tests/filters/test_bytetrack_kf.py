"""bboxtune.filters.bytetrack_kf: ByteTrack's / DeepSORT's box Kalman filter, batched, against a per-frame reference written
from the published equations (initiate / predict / update with 8×8 matrices and Cholesky solves, as the original); its
compiled recursion (bboxtune.filters.box_kf_kernels) against the numpy one, bit for bit; its gap policy
(bboxtune.filters.gap_output) against the damped constant-velocity model worked out per frame."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters import jit
from bboxtune.filters.base import Carry
from bboxtune.filters.box_online import OnlineBoxKF
from bboxtune.filters.bytetrack_kf import GAP_DECAYS, STD_RANGE
from tests.kernel_modes import both

TAU = 1 / 30
PARAMS = ("std_weight_position", "std_weight_velocity", "std_aspect", "std_aspect_rate", "std_aspect_measurement")


class ReferenceKF:
    """ByteTrack's ``KalmanFilter`` as its equations state it ([Zhang-ByteTrack]; notes/mot-baselines.md), one track."""

    def __init__(self, w_p: float = 1 / 20, w_v: float = 1 / 160, s_a: float = 1e-2, s_r: float = 1e-5,
                 s_m: float = 1e-1) -> None:
        self.w_p, self.w_v, self.s_a, self.s_r, self.s_m = w_p, w_v, s_a, s_r, s_m
        self.F = np.eye(8)
        self.F[:4, 4:] = np.eye(4)  # dt = 1 frame
        self.H = np.eye(4, 8)

    def initiate(self, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h = m[3]
        std = [2 * self.w_p * h, 2 * self.w_p * h, self.s_a, 2 * self.w_p * h,
               10 * self.w_v * h, 10 * self.w_v * h, self.s_r, 10 * self.w_v * h]
        return np.r_[m, np.zeros(4)], np.diag(np.square(std))

    def predict(self, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h = mean[3]
        std = [self.w_p * h, self.w_p * h, self.s_a, self.w_p * h, self.w_v * h, self.w_v * h, self.s_r, self.w_v * h]
        Q = np.diag(np.square(std))
        return mean @ self.F.T, np.linalg.multi_dot((self.F, cov, self.F.T)) + Q

    def update(self, mean: np.ndarray, cov: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h = mean[3]
        R = np.diag(np.square([self.w_p * h, self.w_p * h, self.s_m, self.w_p * h]))
        S = np.linalg.multi_dot((self.H, cov, self.H.T)) + R  # "project"
        chol = scipy.linalg.cho_factor(S, lower=True, check_finite=False)
        K = scipy.linalg.cho_solve(chol, (cov @ self.H.T).T, check_finite=False).T
        return mean + (m - self.H @ mean) @ K.T, cov - np.linalg.multi_dot((K, S, K.T))

    def step(self, mean: np.ndarray | None, cov: np.ndarray | None,
             box: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """One frame of a track: initiate at its first detection, then predict, and update on a detection."""
        cx, cy, w, h = box
        m = np.array([cx, cy, w / h, h])
        if mean is None:
            return (None, None) if np.isnan(h) else self.initiate(m)
        mean, cov = self.predict(mean, cov)
        return (mean, cov) if np.isnan(h) else self.update(mean, cov, m)

    def run(self, boxes: np.ndarray) -> np.ndarray:
        """Boxes (T, 4) (cx, cy, w, h), NaN rows missing → states (T, 8): boxes, then their rates per second."""
        out = np.full((len(boxes), 8), np.nan)
        mean = cov = None
        for t, box in enumerate(boxes):
            mean, cov = self.step(mean, cov, box)
            if mean is not None:
                x, y, a, h, vx, vy, va, vh = mean
                out[t] = [x, y, a * h, h, vx / TAU, vy / TAU, (va * h + a * vh) / TAU, vh / TAU]
        return out


def boxes(n_tracks: int, T: int, seed: int, missing: float = 0.2) -> np.ndarray:
    """Random-walk boxes (B, T, 4) with a share ``missing`` of frames missing (whole rows)."""
    rng = np.random.default_rng(seed)
    y = np.empty((n_tracks, T, 4))
    y[..., :2] = 300 + np.cumsum(rng.normal(0, 3, (n_tracks, T, 2)), axis=1)
    y[..., 2:] = rng.uniform(20, 120, (n_tracks, 1, 2)) * np.exp(np.cumsum(rng.normal(0, 0.02, (n_tracks, T, 2)), 1))
    y[rng.random((n_tracks, T)) < missing] = np.nan
    return y


def random_params(n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    defaults = filters.filter_class("bytetrack_kf").DEFAULTS
    return {k: defaults[k] * 10 ** rng.uniform(-1, 1, n) for k in PARAMS}


def random_decays(n: int, seed: int) -> dict[str, np.ndarray]:
    """Gap decays per track: 0, 1 or uniform in between."""
    rng = np.random.default_rng(seed)
    return {k: rng.choice([0.0, 1.0, *rng.uniform(0, 1, 2)], n) for k in GAP_DECAYS}


def assert_matches_reference(y: np.ndarray, states: np.ndarray, params: dict[str, np.ndarray]) -> None:
    for b in range(len(y)):
        ref = ReferenceKF(*(float(np.broadcast_to(params[k], len(y))[b]) for k in PARAMS)).run(y[b])
        np.testing.assert_array_equal(np.isnan(states[b]), np.isnan(ref))
        scale = np.nanmax(np.abs(ref), axis=0, initial=1.0)  # rates near 0: relative to the column's scale
        assert np.nanmax(np.abs(states[b] - ref) / scale, initial=0.0) <= 1e-9


def test_matches_the_reference_on_random_tracks_with_missing_frames_and_per_track_parameters() -> None:
    y = boxes(12, 80, 0)
    y[1, :10] = np.nan  # starts late
    y[2, 30:60] = np.nan  # a long gap
    y[3] = np.nan  # never detected
    params = random_params(12, 1)
    states = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **params).run(y)
    assert states.shape == (12, 80, 8)
    assert_matches_reference(y, states, params)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 60), st.floats(0.0, 0.9), st.booleans(),
       st.integers(0, 60), st.booleans())
def test_the_compiled_recursion_equals_the_numpy_one_bit_for_bit(seed: int, B: int, T: int, missing: float,
                                                                 tuned: bool, split: int, gapped: bool) -> None:
    """Runs, positions and a run continued from a carry (late starts, gaps, tracks never detected; the published or
    random per-track weights; without or with random per-track gap decays): the kernel and the reference give the
    same bits (the env's episodes and rewards do not depend on ``$BBOXTUNE_JIT``)."""
    y = boxes(B, T, seed, missing)
    params = {**(random_params(B, seed) if tuned else {}), **(random_decays(B, seed) if gapped else {})}
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **params)
    cut = min(split, T)

    def runs() -> list[np.ndarray]:
        first, carry = flt.run_from(y[:, :cut])
        rest, end = flt.run_from(y[:, cut:], carry)
        return [flt.run(y), flt.positions(y), first, rest, end.x, end.P, end.missed]

    kernel, reference = both(runs)
    for got, want in zip(kernel, reference, strict=True):
        np.testing.assert_array_equal(got, want)


def test_defaults_are_the_published_weights_and_match_the_reference() -> None:
    assert filters.filter_class("bytetrack_kf").DEFAULTS == {
        "std_weight_position": 1 / 20, "std_weight_velocity": 1 / 160, "std_aspect": 1e-2, "std_aspect_rate": 1e-5,
        "std_aspect_measurement": 1e-1, "gap_velocity_decay": 1.0, "gap_size_decay": 1.0}
    y = boxes(3, 50, 2)
    y[:, 0] = np.nan  # first frame missing
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4))
    states = flt.run(y)
    assert_matches_reference(y, states, flt.DEFAULTS)
    assert np.isnan(states[:, 0]).all()
    np.testing.assert_array_equal(flt.run(y[0]), states[0])  # (T, 4) input: (T, 8)
    np.testing.assert_array_equal(flt.positions(y), states[..., :4])


def test_per_track_parameter_arrays_equal_separate_runs() -> None:
    y, params = boxes(5, 60, 3), random_params(5, 4)
    model = filters.constant_velocity(TAU, ndim=4)
    together = filters.make("bytetrack_kf", model, **params).run(y)
    for b in range(5):
        alone = filters.make("bytetrack_kf", model, **{k: v[b] for k, v in params.items()}).run(y[b])
        np.testing.assert_array_equal(together[b], alone)


def test_empty_batches_and_tracks_without_detections() -> None:
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4))
    assert flt.run(np.empty((0, 10, 4))).shape == (0, 10, 8)
    assert flt.run(np.empty((3, 0, 4))).shape == (3, 0, 8)
    assert flt.positions(np.empty((0, 4))).shape == (0, 4)
    states, carry = flt.run_from(np.full((2, 7, 4), np.nan))
    assert np.isnan(states).all() and np.isnan(carry.x).all() and not carry.measured.any()
    states, carry = flt.run_from(np.empty((2, 0, 4)))
    assert states.shape == (2, 0, 8) and carry.x.shape == (2, 8)


def test_run_from_split_equals_the_whole_run() -> None:
    y, params = boxes(6, 90, 5), random_params(6, 6)
    y[0, :50] = np.nan  # starts after the split
    y[1, 35:45] = np.nan  # a gap across the split
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **params)
    whole = flt.run(y)
    first, carry = flt.run_from(y[:, :40])
    assert carry.x.shape == (6, 8) and carry.P.shape == (6, 8, 8)
    rest, end = flt.run_from(y[:, 40:], carry)
    np.testing.assert_allclose(np.concatenate([first, rest], axis=1), whole, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(first, whole[:, :40])
    # one state continued by several candidates (as the re-tuning env does): each switches parameters at the split
    _, carry1 = filters.make("bytetrack_kf", flt.model).run_from(y[2:3, :40])
    cand = {k: v[:3] for k, v in params.items()}
    est, _ = filters.make("bytetrack_kf", flt.model, **cand).positions_from(y[2:3, 40:].repeat(3, 0), carry1.repeat(3))
    for i in range(3):
        mean = cov = None
        for t in range(40):
            mean, cov = ReferenceKF().step(mean, cov, y[2, t])  # the defaults up to the split ...
        after = ReferenceKF(*(float(cand[k][i]) for k in PARAMS))  # ... then candidate i's parameters
        for t in range(40, 90):
            mean, cov = after.step(mean, cov, y[2, t])
            np.testing.assert_allclose(est[i, t - 40], [mean[0], mean[1], mean[2] * mean[3], mean[3]], rtol=1e-9)


def test_chunks_of_tracks_equal_one_call(monkeypatch: pytest.MonkeyPatch) -> None:
    y, params = boxes(7, 30, 14), random_params(7, 15)
    y[3, :20] = np.nan
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **params)
    whole, carry = flt.run_from(y)
    monkeypatch.setattr(filters.bytetrack_kf, "CHUNK_SAMPLES", 2 * 30 * 4)  # two tracks a chunk
    chunked, chunked_carry = flt.run_from(y)
    np.testing.assert_array_equal(chunked, whole)
    for field in ("x", "P", "y_last", "measured"):
        np.testing.assert_array_equal(getattr(chunked_carry, field), getattr(carry, field))
    np.testing.assert_allclose(flt.run_from(y, carry)[0], flt.run(np.concatenate([y, y], axis=1))[:, 30:], rtol=1e-12,
                               atol=1e-9)


def test_frame_units_and_the_batch_runners() -> None:
    ys, taus = [boxes(1, 60, 7)[0], boxes(1, 40, 8)[0], boxes(1, 60, 9)[0]], [1 / 30, 0.1, 0.04]
    params = random_params(3, 10)
    est = filters.track_positions("bytetrack_kf", ys, taus, params)
    for i in range(3):
        alone = filters.make("bytetrack_kf", filters.constant_velocity(taus[i], ndim=4),
                             **{k: v[i] for k, v in params.items()}).positions(ys[i])
        np.testing.assert_allclose(est[i], alone, rtol=1e-12)
    cand = filters.candidate_positions("bytetrack_kf", ys[0], 1 / 30, params)
    assert cand.shape == (3, 60, 4)
    np.testing.assert_allclose(cand[1], filters.make("bytetrack_kf", filters.constant_velocity(0.5, ndim=4),
                                                     **{k: v[1] for k, v in params.items()}).positions(ys[0]))
    a = filters.make("bytetrack_kf", filters.constant_velocity(0.1, ndim=4)).run(ys[0])
    b = filters.make("bytetrack_kf", filters.constant_velocity(1.0, ndim=4)).run(ys[0])
    np.testing.assert_array_equal(a[:, :4], b[:, :4])
    np.testing.assert_allclose(a[:, 4:] * 0.1, b[:, 4:], rtol=1e-14)  # velocities: per frame / τ


def test_extreme_parameters_stay_finite() -> None:
    y = boxes(8, 200, 11, missing=0.5)
    y[:, 100:190] = np.nan
    y[:2, :, 2:] *= 1e20  # huge boxes ...
    y[2:4, :, 2:] *= 1e-25  # ... and tiny ones
    model = filters.constant_velocity(TAU, ndim=4)
    for low_high in [(0, 0), (0, 1), (1, 0), (1, 1)]:
        corner = {k: np.full(8, STD_RANGE[low_high[i % 2]]) for i, k in enumerate(PARAMS)}
        states = filters.make("bytetrack_kf", model, **corner).run(y)
        assert np.isfinite(states[~np.isnan(states[..., 0])]).all()


@pytest.mark.parametrize(("params", "match"), [
    ({"std_weight_position": 0.0}, r"std_weight_position=0.0 is out of range: allowed 1e-12 <= std_weight_position"),
    ({"std_weight_velocity": np.nan}, "std_weight_velocity=nan is out of range"),
    ({"std_aspect": -1e-2}, "std_aspect=-0.01 is out of range"),
    ({"std_aspect_rate": 1e13},
     r"std_aspect_rate=10000000000000.0 is out of range: allowed 1e-12 <= std_aspect_rate <= 1e\+12"),
    ({"std_aspect_measurement": np.array([0.1, 0.0])}, r"array of shape \(2,\) with entry \[1\] = 0.0"),
    ({"std_weight_position": np.ones((2, 2))}, r"shape \(2, 2\); allowed: a scalar or shape \(B,\)"),
    ({"sigma_w": 1.0}, r"unknown parameter\(s\) \['sigma_w'\]"),
    ({"gap_velocity_decay": 1.5}, r"gap_velocity_decay=1.5 is out of range: allowed 0 <= gap_velocity_decay <= 1"),
    ({"gap_size_decay": np.array([0.5, -0.1])}, r"gap_size_decay=array of shape \(2,\) with entry \[1\] = -0.1"),
])
def test_parameter_errors_name_the_parameter_and_its_range(params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **params)


def test_input_errors() -> None:
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), std_weight_position=np.full(2, 0.05))
    y = boxes(2, 5, 12, missing=0.0)
    with pytest.raises(ValueError, match="M=2"):
        filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=2))
    with pytest.raises(ValueError, match=r"shape \(2,\) but y is a single track"):
        flt.run(y[0])
    with pytest.raises(ValueError, match="B=3 tracks"):
        flt.run(boxes(3, 5, 12))
    bad = y.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match=r"y\[1, 2\] = .* is partly NaN"):
        flt.run(bad)
    bad = y.copy()
    bad[0, 3, 3] = 0.0
    with pytest.raises(ValueError, match=r"y\[0, 3\] has h = 0.0; allowed: box sizes w, h >= 1e-30"):
        flt.run(bad)
    with pytest.raises(ValueError, match="no camera states"):
        flt.run(y, u=np.zeros((2, 5, 2)))


@pytest.mark.parametrize("shared", [True, False])
@pytest.mark.parametrize(("row", "value", "match"), [
    ((1, 2, 0), np.nan, r"y\[1, 2\] = .* is partly NaN"), ((0, 3, 3), 0.0, r"y\[0, 3\] has h = 0.0; allowed"),
    ((0, 1, 2), 1e-31, r"y\[0, 1\] has w = 1e-31; allowed"), ((1, 0, 1), np.inf, r"y contains ±inf"),
    ((1, 4, 0), -2e30, r"y contains 2e\+30; allowed")])
def test_positions_name_a_bad_box_as_run_does(shared: bool, row: tuple[int, int, int], value: float, match: str) -> None:
    """The compiled ``positions`` checks the boxes as it reads them (shared parameters: no other check first); a bad
    box gets the recursion's error, for a batch and for one track."""
    params = {} if shared else {"std_weight_position": np.full(2, 0.05)}
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **params)
    assert (flt._shared_stds is not None) == shared
    bad = boxes(2, 5, 12, missing=0.0)
    bad[row] = value
    for call in (flt.run, flt.positions):
        with pytest.raises(ValueError, match=match):
            call(bad)
    if shared:
        with pytest.raises(ValueError, match=match.replace(rf"y\[{row[0]}, ", r"y\[0, ")):
            flt.positions(bad[row[0]][None])


def test_shared_parameters_give_the_per_track_boxes_bit_for_bit() -> None:
    """One value for every track (the direct kernel call) and the same values per track (the checked path), for a
    batch and for one track."""
    y = boxes(4, 50, 3)
    weights = {"std_weight_position": 0.03, "std_aspect_measurement": 0.2}
    shared = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **weights)
    per_track = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4),
                             **{k: np.full(4, v) for k, v in weights.items()})
    assert shared._shared_stds is not None and per_track._shared_stds is None
    np.testing.assert_array_equal(shared.positions(y), per_track.positions(y))
    np.testing.assert_array_equal(shared.positions(y[2]), per_track.positions(y)[2])
    np.testing.assert_array_equal(shared.positions(y[2]), shared.run(y[2])[:, :4])


def test_carry_errors() -> None:
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4))
    y = boxes(2, 5, 13, missing=0.0)
    _, carry = flt.run_from(y)
    with pytest.raises(ValueError, match=r"carry.x has shape \(2, 8\); allowed: \(3, 8\)"):
        flt.run_from(boxes(3, 5, 13), carry)
    with pytest.raises(ValueError, match="allowed: None or a bboxtune.filters.base.Carry"):
        flt.run_from(y, {"x": carry.x})
    x = carry.x.copy()
    x[0, 5] = np.nan
    with pytest.raises(ValueError, match="finite in all 8 entries"):
        flt.run_from(y, Carry(x=x, P=carry.P, y_last=carry.y_last, measured=carry.measured))
    P = carry.P.copy()
    P[:, 0, 1] = P[:, 1, 0] = 1.0
    with pytest.raises(ValueError, match="carry.P couples different coordinates"):
        flt.run_from(y, Carry(x=carry.x, P=P, y_last=carry.y_last, measured=carry.measured))


def test_the_gap_policy_follows_the_damped_model_and_leaves_the_detected_frames_alone() -> None:
    """Inside a gap the output starts from the last detected frame's estimate and moves on at a velocity that decays
    by ρ^τ a frame (the centre: ``gap_velocity_decay``; the size held for ``gap_size_decay`` = 0); every detected
    frame, and the first frame after a gap, is the stock filter's."""
    y = boxes(4, 70, 16, missing=0.0)
    y[:, 30:45] = np.nan
    y[1, 50:70] = np.nan  # trailing frames without a detection: predicted too
    model = filters.constant_velocity(TAU, ndim=4)
    stock = filters.make("bytetrack_kf", model).run(y)
    rho = 0.3
    states = filters.make("bytetrack_kf", model, gap_velocity_decay=rho, gap_size_decay=0.0).run(y)
    detected = ~np.isnan(y[..., 0])
    np.testing.assert_array_equal(states[detected], stock[detected])
    d = rho**TAU
    for b, gap in [(0, range(30, 45)), (1, range(30, 45)), (1, range(50, 70))]:
        last = gap[0] - 1
        for k, t in enumerate(gap, start=1):
            travelled = sum(d**i for i in range(1, k + 1))
            want = [*(stock[b, last, :2] + stock[b, last, 4:6] * TAU * travelled), *stock[b, last, 2:4],
                    *(stock[b, last, 4:6] * d**k), 0.0, 0.0]
            np.testing.assert_allclose(states[b, t], want, rtol=1e-12, atol=1e-9)
    assert not np.allclose(states[0, 44, :2], stock[0, 44, :2])  # the policy changed the gap output


def test_the_default_gap_policy_is_the_filter_bit_for_bit() -> None:
    y = boxes(5, 80, 17, missing=0.4)
    model = filters.constant_velocity(TAU, ndim=4)
    stock = filters.make("bytetrack_kf", model).run(y)
    explicit = filters.make("bytetrack_kf", model, gap_velocity_decay=1.0, gap_size_decay=np.ones(5)).run(y)
    np.testing.assert_array_equal(explicit, stock)
    held = filters.make("bytetrack_kf", model, gap_velocity_decay=0.0, gap_size_decay=0.0).positions(y)
    missing = np.isnan(y[..., 0]) & ~np.isnan(stock[..., 0])
    assert np.abs(held - stock[..., :4])[missing].max() > 1.0  # the policy reaches the gap frames ...
    assert (np.diff(held[:, :, 3], axis=1)[missing[:, 1:]] == 0).all()  # ... and holds the height there


def test_the_gap_decay_is_per_second_across_frame_rates_and_in_the_batch_runners() -> None:
    """The same ρ gives the same output at any τ that the per-frame factor ρ^τ makes equal; the batch runners
    (frame units, tracks of several τ in one call) equal a filter built at each τ."""
    y = boxes(1, 60, 18, missing=0.3)[0]
    decays = {"gap_velocity_decay": 0.4, "gap_size_decay": 0.2}
    a = filters.make("bytetrack_kf", filters.constant_velocity(0.1, ndim=4), **decays).positions(y)
    b = filters.make("bytetrack_kf", filters.constant_velocity(1.0, ndim=4),
                     **{k: v**0.1 for k, v in decays.items()}).positions(y)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    ys, taus = [y, boxes(1, 60, 19)[0], boxes(1, 45, 20)[0]], [1 / 30, 0.1, 0.04]
    params = {**random_params(3, 21), **random_decays(3, 22)}
    est = filters.track_positions("bytetrack_kf", ys, taus, params)
    for i in range(3):
        alone = filters.make("bytetrack_kf", filters.constant_velocity(taus[i], ndim=4),
                             **{k: v[i] for k, v in params.items()}).positions(ys[i])
        np.testing.assert_allclose(est[i], alone, rtol=1e-12)


def test_run_from_continues_the_gap_output_across_the_split() -> None:
    y = boxes(4, 90, 23, missing=0.2)
    y[:, 32:52] = np.nan  # a gap across the split at 40
    y[3, :60] = np.nan  # starts after the split
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **random_decays(4, 24))
    whole = flt.run(y)
    first, carry = flt.run_from(y[:, :40])
    np.testing.assert_array_equal(carry.missed[:, 0], [8, 8, 8, 0])  # frames since the last detection
    rest, end = flt.run_from(y[:, 40:], carry)
    np.testing.assert_allclose(np.concatenate([first, rest], axis=1), whole, rtol=1e-12, atol=1e-9)
    bad = Carry(x=carry.x, P=carry.P, y_last=carry.y_last, measured=carry.measured, missed=carry.missed + 0.5)
    with pytest.raises(ValueError, match="carry.missed: allowed the frames since a track's last detection"):
        flt.run_from(y[:, 40:], bad)


def test_a_tracker_refuses_a_gap_policy() -> None:
    model = filters.constant_velocity(TAU, ndim=4)
    with pytest.raises(ValueError, match="gap_velocity_decay=0.5: the gap policy shapes a smoothed track's output"):
        OnlineBoxKF(filters.make("bytetrack_kf", model, gap_velocity_decay=0.5))
    kf = OnlineBoxKF(filters.make("bytetrack_kf", model))
    kf.start(np.array([[50.0, 60.0, 20.0, 40.0]]))
    with pytest.raises(ValueError, match="gap_size_decay=0.0"):
        kf.set_params(np.array([0]), {"gap_size_decay": 0.0})


def test_compiled_positions_leave_a_non_finite_estimate_to_the_recursion(monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernel of ``positions`` reports a non-finite estimate after a track's start; the recursion then runs and
    raises its error naming the track and frame (here: it runs, and gives the same boxes)."""
    monkeypatch.setattr(jit, "ENABLED", True)  # the kernels, whatever $BBOXTUNE_JIT says
    y = boxes(3, 40, 21)
    flt = filters.make("bytetrack_kf", filters.constant_velocity(TAU, ndim=4), **random_params(3, 22))
    calls: list[int] = []

    def failing(Y: np.ndarray, *args: np.ndarray) -> bool:
        calls.append(len(Y))
        return False

    want = flt.positions(y)
    monkeypatch.setattr(filters.box_kf_kernels, "bytetrack_positions", failing)
    np.testing.assert_array_equal(flt.positions(y), want)
    assert calls == [3]
