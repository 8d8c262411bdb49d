"""Every back end at the edges of its documented parameter range (bboxtune.filters.validation): finite output over the
whole range, a ValueError naming the parameter just outside it, empty batches and tracks, chunked batches equal
to unchunked ones, bounded working memory, and the UKF as accurate as the KF where the uncentred UKF was not."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from bboxtune import filters
from bboxtune.filters.validation import PRIOR_MAX, PSI_MAX, SIGMA_RANGE, TAU_RANGE, VALUE_MAX, VARIANCE_MAX

KALMAN = ("kf", "kf_cmn", "ukf")
WINDOW = ("ofir", "oufir", "fir")


def log_uniform(low: float, high: float) -> st.SearchStrategy[float]:
    """Floats spread evenly in log scale over [low, high], the bounds themselves included."""
    inner = st.floats(math.log10(low), math.log10(high)).map(lambda e: min(max(10.0**e, low), high))
    return st.one_of(st.sampled_from([low, high]), inner)


SIGMA = log_uniform(*SIGMA_RANGE)


@st.composite
def measurements(draw: st.DrawFn, M: int = 2) -> np.ndarray:
    """(2, T, M) tracks of any level and spread within ±VALUE_MAX, some frames missing (whole boxes)."""
    T = draw(st.integers(1, 60))
    level = draw(st.sampled_from([-1.0, 1.0])) * draw(log_uniform(1e-30, 0.5 * VALUE_MAX))
    spread = draw(log_uniform(1e-30, 0.05 * VALUE_MAX))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    walk = np.cumsum(rng.normal(size=(2, T, M)), axis=1)
    y = level + spread * walk / max(1.0, float(np.max(np.abs(walk))))
    y[rng.random((2, T)) < draw(st.sampled_from([0.0, 0.1, 0.4]))] = np.nan
    return y


def params_strategy(name: str) -> st.SearchStrategy[dict]:
    """Random parameters of back end ``name`` over its whole documented range."""
    fields: dict[str, st.SearchStrategy] = {"sigma_w": SIGMA, "sigma_v": SIGMA}
    if name in ("kf_cmn", "ufir_cmn"):
        fields["psi"] = st.one_of(st.sampled_from([0.0, PSI_MAX]), st.floats(0.0, PSI_MAX))
    if name not in KALMAN:
        fields["horizon"] = st.one_of(st.integers(2, 70), st.integers(2, 100_000))
    if name == "ukf":
        fields.update(alpha=log_uniform(1e-4, 1e4), beta=st.floats(0.0, 1e4),
                      kappa=st.one_of(st.sampled_from([np.nextafter(-2.0, 0.0), 1e4]), st.floats(-1.999, 1e4)))
    return st.fixed_dictionaries(fields)


def assert_finite_from_first_measurement(out: np.ndarray, y: np.ndarray) -> None:
    seen = np.maximum.accumulate(np.isfinite(y[..., 0]), axis=1)  # frames at or after the first finite one
    assert np.all(np.isfinite(out[seen])), np.argwhere(~np.isfinite(out) & seen[..., None])[:3]


@pytest.mark.parametrize("name", filters.NAMES)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_whole_documented_range_gives_finite_output(name: str, data: st.DataObject) -> None:
    tau = data.draw(log_uniform(*TAU_RANGE), label="tau")
    params = data.draw(params_strategy(name), label="params")
    y = data.draw(measurements(), label="y")
    model = filters.constant_velocity(tau, ndim=2)
    out = filters.make(name, model, **params).run(y)
    assert_finite_from_first_measurement(out, y)


@pytest.mark.parametrize("name", KALMAN)
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_priors_over_their_range_give_finite_output(name: str, data: st.DataObject) -> None:
    """x0 within ±VALUE_MAX and a diagonal P0 whose frame-unit variances are within [0, PRIOR_MAX] σ_v² (and its
    entries within VARIANCE_MAX): finite output at every frame."""
    tau = data.draw(log_uniform(*TAU_RANGE), label="tau")
    params = data.draw(params_strategy(name), label="params")
    x0 = np.array(data.draw(st.lists(st.floats(-VALUE_MAX, VALUE_MAX), min_size=4, max_size=4), label="x0"))
    scales = data.draw(st.lists(st.one_of(st.just(0.0), log_uniform(1e-60, PRIOR_MAX)), min_size=4, max_size=4),
                       label="P0 diagonal / sigma_v² in frame units")
    P0 = np.diag(np.array(scales) * params["sigma_v"] ** 2 / np.array([1.0, 1.0, tau**2, tau**2]))
    assume(np.all(P0 <= VARIANCE_MAX))
    y = data.draw(measurements(), label="y")
    out = filters.make(name, filters.constant_velocity(tau, ndim=2), x0=x0, P0=P0, **params).run(y)
    assert np.all(np.isfinite(out))


@settings(max_examples=30, deadline=None)
@given(tau=log_uniform(*TAU_RANGE), params=params_strategy("ofir"), low=st.floats(-30, 8),
       high=st.floats(-30, 8), angle=st.floats(0, np.pi), y=measurements(M=1))
def test_ofir_prior_over_its_range_gives_finite_output(tau: float, params: dict, low: float, high: float,
                                                       angle: float, y: np.ndarray) -> None:
    """OFIR's P0: eigenvalues in frame units within sigma_v² · [1e-30, 1e8] (bboxtune.filters.ofir.PRIOR_LOW,
    bboxtune.filters.validation.PRIOR_MAX), entries within ±VARIANCE_MAX."""
    c, s = math.cos(angle), math.sin(angle)
    rotation = np.array([[c, -s], [s, c]])
    with np.errstate(over="ignore"):
        frames = rotation @ np.diag([10.0**low, 10.0**high]) @ rotation.T * params["sigma_v"] ** 2
        P0 = np.diag([1.0, 1.0 / tau]) @ frames @ np.diag([1.0, 1.0 / tau])
    P0 = 0.5 * (P0 + P0.T)
    assume(np.all(np.abs(P0) <= VARIANCE_MAX))
    try:
        flt = filters.make("ofir", filters.constant_velocity(tau), P0=P0, **params)
    except ValueError as exc:  # an eigenvalue just outside the range by rounding, or a prior too ill-conditioned
        assert "P0" in str(exc) and ("eigenvalues" in str(exc) or "Cholesky" in str(exc))  # for Cholesky
        return
    assert_finite_from_first_measurement(flt.run(y), y)


NEXT_OUT = 1.0001  # a factor just outside a bound


@pytest.mark.parametrize(
    ("names", "params", "match"),
    [
        (filters.NAMES, {"sigma_w": SIGMA_RANGE[1] * NEXT_OUT}, "sigma_w=.*allowed 1e-30 <= sigma_w <= 1e\\+30"),
        (filters.NAMES, {"sigma_w": SIGMA_RANGE[0] / NEXT_OUT}, "sigma_w=.*allowed"),
        (filters.NAMES, {"sigma_v": SIGMA_RANGE[1] * NEXT_OUT}, "sigma_v=.*allowed 1e-30 <= sigma_v"),
        (filters.NAMES, {"sigma_v": np.array([1.0, 0.0])}, r"sigma_v=array of shape \(2,\) with entry \[1\] = 0.0"),
        (("kf_cmn", "ufir_cmn"), {"psi": np.nextafter(PSI_MAX, 1.0)}, "psi=.*allowed 0 <= psi <= 0.99"),
        (("kf_cmn", "ufir_cmn"), {"psi": -1e-12}, "psi=.*allowed"),
        (("ufir", "ufir_cmn", *WINDOW), {"horizon": 1}, "horizon=1.*allowed integers 2 <= horizon <= 100000"),
        (("ufir", "ufir_cmn", *WINDOW), {"horizon": 100_001}, "horizon=.*allowed"),
        (("ukf",), {"alpha": 1e-4 / NEXT_OUT}, "alpha=.*allowed 0.0001 <= alpha <= 10000"),
        (("ukf",), {"alpha": 1e4 * NEXT_OUT}, "alpha=.*allowed"),
        (("ukf",), {"beta": -1e-12}, "beta=.*allowed 0 <= beta <= 10000"),
        (("ukf",), {"beta": 1e4 * NEXT_OUT}, "beta=.*allowed"),
        (("ukf",), {"kappa": -2.0}, "kappa=-2.0 is out of range: allowed -2 < kappa <= 10000"),
        (("ukf",), {"kappa": 1e4 * NEXT_OUT}, "kappa=.*allowed"),
        (("ukf",), {"sigma_c": SIGMA_RANGE[1] * NEXT_OUT}, "sigma_c=.*allowed"),
        (("ukf",), {"sigma_u": SIGMA_RANGE[0] / NEXT_OUT}, "sigma_u=.*allowed"),
        (KALMAN, {"x0": np.array([0.0, VALUE_MAX * NEXT_OUT, 0.0, 0.0])}, "x0=.*\\|x0\\| <= 1e\\+30"),
        (KALMAN, {"P0": np.diag([1.0, VARIANCE_MAX * NEXT_OUT, 1.0, 1.0])}, "P0 .*\\|P0\\| <= 1e\\+60"),
    ],
)
def test_just_outside_the_range_names_the_parameter(names: tuple[str, ...], params: dict, match: str) -> None:
    model = filters.constant_velocity(0.5, ndim=2)
    for name in names:
        with pytest.raises(ValueError, match=match):
            filters.make(name, model, **params)


OUTSIDE = {  # parameter -> (back ends, values beyond its documented range)
    "sigma_w": (filters.NAMES, st.one_of(log_uniform(SIGMA_RANGE[1] * NEXT_OUT, 1e300),
                                         log_uniform(1e-300, SIGMA_RANGE[0] / NEXT_OUT), st.just(0.0))),
    "sigma_v": (filters.NAMES, st.one_of(log_uniform(SIGMA_RANGE[1] * NEXT_OUT, 1e300), st.floats(max_value=0.0),
                                         st.sampled_from([np.nan, np.inf]))),
    "psi": (("kf_cmn", "ufir_cmn"), st.one_of(st.floats(PSI_MAX * NEXT_OUT, 1e3), st.floats(-1e3, -1e-300))),
    "horizon": (("ufir", "ufir_cmn", *WINDOW), st.one_of(st.integers(-10**6, 1), st.integers(100_001, 10**9),
                                                        st.floats(2.01, 99.99).filter(lambda v: v != round(v)))),
    "alpha": (("ukf",), st.one_of(log_uniform(1e-300, 1e-4 / NEXT_OUT), log_uniform(1e4 * NEXT_OUT, 1e300))),
    "beta": (("ukf",), st.one_of(st.floats(-1e300, -1e-300), log_uniform(1e4 * NEXT_OUT, 1e300))),
    "kappa": (("ukf",), st.one_of(st.floats(-1e300, -2.0), log_uniform(1e4 * NEXT_OUT, 1e300))),
    "sigma_c": (("ukf",), log_uniform(SIGMA_RANGE[1] * NEXT_OUT, 1e300)),
    "sigma_u": (("ukf",), log_uniform(1e-300, SIGMA_RANGE[0] / NEXT_OUT)),
}


@pytest.mark.parametrize("param", sorted(OUTSIDE))
@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_random_values_outside_the_range_name_the_parameter(param: str, data: st.DataObject) -> None:
    names, values = OUTSIDE[param]
    name = data.draw(st.sampled_from(names), label="back end")
    value = data.draw(values, label=param)
    per_track = data.draw(st.booleans(), label="as a per-track array")
    arg = np.array([1.0, value, 2.0]) if per_track and param != "horizon" else value
    with pytest.raises(ValueError, match=f"^{param}=.*out of range: allowed"):
        filters.make(name, filters.constant_velocity(0.5, ndim=2), **{param: arg})


def test_just_outside_other_ranges() -> None:
    for tau in (TAU_RANGE[0] / NEXT_OUT, TAU_RANGE[1] * NEXT_OUT, 0.0, np.nan):
        with pytest.raises(ValueError, match=r"tau=.*allowed 1e-06 <= tau <= 1e\+06"):
            filters.constant_velocity(tau)
    model = filters.constant_velocity(1.0)
    for P0 in (np.diag([1e-31, 1.0]), np.diag([1.0, 1.01e8])):  # frame-unit eigenvalues / sigma_v² outside
        with pytest.raises(ValueError, match=r"P0 has frame-unit eigenvalues .* allowed eigenvalues within \[1e-30, 1e\+08\]"):
            filters.make("ofir", model, sigma_v=1.0, P0=P0)
    P0 = np.diag([1.0, 1.0, 1.01e8 / 0.25, 1.0])  # velocity of coordinate 0: 1.01e8 sigma_v² in frame units (τ = 0.5)
    for name in KALMAN:
        with pytest.raises(ValueError, match=r"P0 has frame-unit eigenvalues .* allowed eigenvalues within \[0, 1e\+08\]"):
            filters.make(name, filters.constant_velocity(0.5, ndim=2), P0=P0)
        filters.make(name, filters.constant_velocity(0.5, ndim=2), P0=P0 / 1.02)  # just inside
    for name in filters.NAMES:
        flt = filters.make(name, filters.constant_velocity(0.1, ndim=2))
        for bad, text in ((VALUE_MAX * NEXT_OUT, "contains 1e\\+30"), (np.inf, "contains ±inf"),
                          (-np.inf, "contains ±inf")):
            y = np.zeros((5, 2))
            y[3, 1] = bad
            with pytest.raises(ValueError, match=f"y {text}.*allowed: finite values with \\|y\\| <= 1e\\+30"):
                flt.run(y)
    camera = filters.make("ukf", filters.constant_velocity(0.1, ndim=2), camera_motion=True)
    with pytest.raises(ValueError, match="u contains"):
        camera.run(np.zeros((5, 2)), u=np.full((5, 2), 2e30))
    with pytest.raises(ValueError, match="sigma_w=1e\\+31"):
        filters.n_opt(1.0, 1e31, 0.1)


def test_ukf_with_huge_measurement_noise_follows_the_kf() -> None:
    """σ_v = 1e20 on a 200 px track: the uncentred sigma points returned 2e4 px; the UKF must agree with the KF
    at the same tuning (a least-squares line through the data, positions within the track's range)."""
    rng = np.random.default_rng(0)
    t = np.arange(300)
    y = np.stack([200.0 + 0.1 * t, 150.0 - 0.05 * t], axis=1) + rng.normal(0.0, 2.0, (300, 2))
    model = filters.constant_velocity(1 / 30, ndim=2)
    for sigma_v in (1e10, 1e20, 1e30):
        ukf = filters.make("ukf", model, sigma_v=sigma_v).run(y)
        kf = filters.make("kf", model, sigma_v=sigma_v).run(y)
        assert np.max(np.abs(ukf[:, :2] - kf[:, :2])) < 1e-9 * np.max(np.abs(kf[:, :2]))
        assert np.all((ukf[1:, :2] > 100.0) & (ukf[1:, :2] < 300.0))


def test_ukf_at_huge_noise_ratios_follows_the_kf() -> None:
    rng = np.random.default_rng(1)
    y = 100.0 + np.cumsum(rng.normal(size=(2, 200, 1)), axis=1)
    y[0, 50:53] = np.nan
    model = filters.constant_velocity(1.0)
    for sigma_w in (1e-30, 1e-10, 1e10, 1e30):
        ukf = filters.make("ukf", model, sigma_w=sigma_w).run(y)
        kf = filters.make("kf", model, sigma_w=sigma_w).run(y)
        np.testing.assert_allclose(ukf[..., 0], kf[..., 0], rtol=1e-12, atol=1e-12 * np.max(np.abs(y[0, :5])))


@pytest.mark.parametrize("name", filters.NAMES)
def test_empty_batches_and_tracks(name: str) -> None:
    model = filters.constant_velocity(0.1, ndim=4)
    flt = filters.make(name, model)
    assert flt.run(np.zeros((0, 50, 4))).shape == (0, 50, 8)
    assert flt.positions(np.zeros((0, 50, 4))).shape == (0, 50, 4)
    assert flt.run(np.zeros((3, 0, 4))).shape == (3, 0, 8)
    assert flt.run(np.zeros((0, 4))).shape == (0, 8)
    assert flt.positions(np.zeros((0, 0, 4))).shape == (0, 0, 4)
    per_track = "sigma_v" if name in KALMAN else "horizon"
    empty = filters.make(name, model, **{per_track: np.array([], dtype=float if per_track == "sigma_v" else int)})
    assert empty.run(np.zeros((0, 20, 4))).shape == (0, 20, 8)
    if name not in KALMAN:
        states, history = flt.run_from(np.zeros((0, 50, 4)))
        assert states.shape == (0, 50, 8) and history.y.shape == (0, 50, 4)
        states, history = flt.run_from(np.zeros((2, 0, 4)))
        assert states.shape == (2, 0, 8) and history.y.shape == (2, 0, 4)
        return
    states, carry = flt.run_from(np.zeros((0, 50, 4)))
    assert states.shape == (0, 50, 8) and carry.x.shape == (0, 8) and carry.P.shape == (0, 8, 8)
    states, carry = flt.run_from(np.zeros((0, 50, 4)), carry)
    assert states.shape == (0, 50, 8) and carry.y_last.shape == (0, 4)
    y = np.random.default_rng(0).normal(size=(2, 30, 4))
    first, carry = flt.run_from(y)
    none, same = flt.run_from(np.zeros((2, 0, 4)), carry)  # zero frames: the carry passes through
    assert none.shape == (2, 0, 8) and np.array_equal(same.x, carry.x) and np.array_equal(same.P, carry.P)
    _, fresh = flt.run_from(np.zeros((2, 0, 4)))  # ... or a carry of tracks that have not started
    assert np.isnan(fresh.x).all() and not fresh.measured.any()
    rest, _ = flt.run_from(y, fresh)
    np.testing.assert_array_equal(rest, flt.run(y))


CHUNK_PARAMS = {
    "kf": {"sigma_w": np.geomspace(1.0, 300.0, 7), "sigma_v": 3.0},
    "kf_cmn": {"sigma_w": 40.0, "sigma_v": np.geomspace(0.5, 9.0, 7), "psi": np.linspace(0.0, 0.95, 7)},
    "ufir": {"horizon": np.array([2, 5, 9, 20, 40, 80, 3])},
    "ufir_cmn": {"horizon": np.array([2, 5, 9, 20, 40, 80, 3]), "psi": np.linspace(0.0, 0.95, 7)},
    "ofir": {"horizon": np.array([2, 5, 9, 20, 40, 80, 3]), "sigma_w": np.geomspace(1.0, 300.0, 7)},
    "oufir": {"horizon": np.array([2, 5, 9, 20, 40, 80, 3]), "sigma_w": np.geomspace(1.0, 300.0, 7)},
    "fir": {"horizon": np.array([2, 5, 9, 20, 40, 80, 3]), "sigma_w": np.geomspace(1.0, 300.0, 7)},
    "ukf": {"sigma_w": np.geomspace(1.0, 300.0, 7), "sigma_v": 3.0, "alpha": 0.5},
}


@pytest.mark.parametrize("name", filters.NAMES)
def test_chunked_batches_equal_one_pass(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Batches beyond CHUNK_SAMPLES channel-frames run in chunks of tracks: the same estimates to rounding. The
    gain recursions of the Kalman family group a chunk's rows differently (~1e-13; the ukf one-row path ~1e-11);
    UFIR's windows with missing samples solve normal equations summed by FFTs whose length follows the longest
    horizon in the chunk, and at ψ = 0.95 with N = 3 they are accurate to ~1e-9 only (the same difference as one
    track filtered alone vs in this batch; measured against the literal Algorithm 2: 2e-7 absolute on 500)."""
    rng = np.random.default_rng(3)
    y = 50.0 + np.cumsum(rng.normal(size=(7, 120, 2)), axis=1)
    y[rng.random((7, 120)) < 0.1] = np.nan
    y[2, :15] = np.nan
    flt = filters.make(name, filters.constant_velocity(1 / 25, ndim=2), **CHUNK_PARAMS[name])
    whole, positions = flt.run(y), flt.positions(y)
    monkeypatch.setattr(filters.base, "CHUNK_SAMPLES", 2 * 120 * 2)  # 2 tracks per chunk
    tol = {"ukf": 1e-10, "ufir": 1e-9, "ufir_cmn": 1e-9}.get(name, 1e-12)
    for got, want in ((flt.run(y), whole), (flt.positions(y), positions)):
        assert np.array_equal(np.isnan(got), np.isnan(want))
        for part in (slice(0, 2), slice(2, 4)) if got.shape[-1] == 4 else (slice(0, 2),):
            scale = np.nanmax(np.abs(want[..., part]))
            assert np.nanmax(np.abs(got[..., part] - want[..., part])) <= tol * scale
    if name in KALMAN:
        first, carry = flt.run_from(y[:, :70])
        rest, end = flt.run_from(y[:, 70:], carry)
        assert np.nanmax(np.abs(np.concatenate([first, rest], axis=1) - whole)) <= tol * np.nanmax(np.abs(whole))
        assert end.x.shape == (7, 4)


@pytest.mark.parametrize("name", ["ufir", "ofir", "kf"])
def test_working_memory_does_not_grow_with_the_batch(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Peak allocations beyond the input and the result (tracemalloc, numpy's allocations included) stay about the
    same for a 4× larger batch with missing frames: the batch runs in chunks of CHUNK_SAMPLES channel-frames
    (UFIR's NaN windows once took ~300 bytes per channel-frame for the whole batch at once: 12 GB at 20,000 ×
    500 boxes)."""
    monkeypatch.setattr(filters.base, "CHUNK_SAMPLES", 1 << 14)
    flt = filters.make(name, filters.constant_velocity(1 / 30, ndim=4), horizon=30) if name != "kf" else \
        filters.make(name, filters.constant_velocity(1 / 30, ndim=4))
    extra = []
    for n_tracks in (100, 400):
        rng = np.random.default_rng(n_tracks)
        y = 100.0 + np.cumsum(rng.normal(size=(n_tracks, 100, 4)), axis=1)
        y[rng.random((n_tracks, 100)) < 0.05] = np.nan
        flt.run(y[:2])  # gains cached outside the measurement
        tracemalloc.start()
        out = flt.run(y)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        extra.append(peak - out.nbytes)
    assert extra[1] < 1.5 * extra[0], extra
