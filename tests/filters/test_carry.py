"""``Filter.run_from`` / :class:`bboxtune.filters.base.Carry` (kf, kf_cmn, ukf): a run split into pieces equals the
whole run, ``Carry.repeat`` broadcasts one state to candidate parameter sets, a parameter change between
pieces matches an explicit filterpy loop that switches parameters at that frame, and bad carries are refused."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from bboxtune import filters
from bboxtune.filters.base import Carry
from tests.filters.test_kf import assert_rel, simulate
from tests.filters.test_kf_cmn import cmn_matrices

TAU = 0.05
B, T, M = 3, 120, 2
CONFIGS = {  # per-track parameter arrays (B,)
    "kf": {"sigma_w": np.array([5.0, 30.0, 300.0]), "sigma_v": np.array([2.0, 0.5, 4.0])},
    "kf_cmn": {"sigma_w": np.array([5.0, 30.0, 300.0]), "sigma_v": np.array([2.0, 0.5, 4.0]),
               "psi": np.array([0.0, 0.6, 0.95])},
    "ukf": {"sigma_w": np.array([5.0, 30.0, 300.0]), "sigma_v": np.array([2.0, 0.5, 4.0]),
            "alpha": np.array([1.0, 0.5, 1.0])},
    "ukf_camera": {"sigma_w": np.array([5.0, 30.0, 300.0]), "sigma_v": np.array([2.0, 0.5, 4.0]),
                   "camera_motion": True, "sigma_c": np.array([50.0, 5.0, 1.0]), "sigma_u": 2.0},
}
# next to missing frames: track 0 misses frames 39–40, track 1 coordinate 1 misses 60–62, track 2 starts at 70
SPLITS = [1, 39, 40, 41, 61, 63, 70, 71, 119]


def make(config: str, model: filters.StateSpaceModel, **params: object) -> filters.Filter:
    return filters.make(config.removesuffix("_camera"), model, **{**CONFIGS[config], **params})


def data(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Measurements (B, T, M) with the gaps of SPLITS, and a camera velocity (B, T, M) with gaps."""
    rng = np.random.default_rng(seed)
    y = simulate(rng, T, M, 20.0, 2.0, B=B)
    y[0, 39:41] = np.nan
    y[1, 60:63, 1] = np.nan
    y[2, :70] = np.nan
    u = rng.normal(size=(B, T, M)) * 10.0
    u[0, :3] = np.nan
    u[1, 50:55] = np.nan
    return y, u


def run_in_pieces(f: filters.Filter, y: np.ndarray, cuts: list[int], u: np.ndarray | None = None,
                  carry: Carry | None = None) -> tuple[np.ndarray, Carry]:
    """run_from over y[..., a:b, :] for consecutive pieces [0, cuts..., T), carrying the state."""
    parts = []
    bounds = [0, *cuts, y.shape[-2]]
    for a, b in zip(bounds[:-1], bounds[1:], strict=False):
        states, carry = f.run_from(y[..., a:b, :], carry, u=None if u is None else u[..., a:b, :])
        parts.append(states)
    return np.concatenate(parts, axis=-2), carry


def assert_same(a: np.ndarray, b: np.ndarray, tol: float = 1e-12) -> None:
    """Equal NaN pattern; finite entries equal to ``tol`` relative to max |b|."""
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    assert_rel(a[~np.isnan(a)], b[~np.isnan(b)], tol)


def assert_same_carry(a: Carry, b: Carry, tol: float = 1e-12) -> None:
    np.testing.assert_array_equal(a.measured, b.measured)
    for name in ("x", "P", "y_last", "missed", "c", "P_c"):
        if getattr(b, name) is None:
            assert getattr(a, name) is None
        else:
            assert_same(getattr(a, name), getattr(b, name), tol)


@pytest.mark.parametrize("prior", [False, True])
@pytest.mark.parametrize("config", list(CONFIGS))
def test_pieces_equal_the_whole_run(config: str, prior: bool) -> None:
    y, u = data()
    model = filters.constant_velocity(TAU, ndim=M)
    extra = {"x0": np.r_[np.full(M, 100.0), np.zeros(M)], "P0": np.eye(2 * M) * 50.0} if prior else {}
    f = make(config, model, **extra)
    u = u if config == "ukf_camera" else None
    whole = f.run(y, u=u)
    first, carry_whole = f.run_from(y, None, u=u)
    np.testing.assert_array_equal(first, whole)  # carry None: the start of every track
    assert carry_whole.x.shape == (B, 2 * M) and carry_whole.P.shape == (B, 2 * M, 2 * M)
    assert (carry_whole.c is not None) == (config == "ukf_camera")
    for t in SPLITS:
        pieces, carry = run_in_pieces(f, y, [t], u)
        assert_same(pieces, whole)
        assert_same_carry(carry, carry_whole)
    pieces, carry = run_in_pieces(f, y, [10, 40, 41, 69, 100], u)  # a chain of carries
    assert_same(pieces, whole)
    assert_same_carry(carry, carry_whole)
    if not prior:
        _, early = f.run_from(y[:, :50], None, u=None if u is None else u[:, :50])
        blocks = np.kron(np.ones((2, 2)), np.eye(M)).astype(bool)  # the per-coordinate entries of P
        assert np.all(np.isnan(early.x[2])) and np.array_equal(np.isnan(early.P[2]), blocks)  # not started
        np.testing.assert_array_equal(early.y_last, y[:, 49])


@pytest.mark.parametrize("config", ["kf", "kf_cmn", "ukf"])
def test_one_track_carry_repeated_for_candidates(config: str) -> None:
    y, _ = data(1)
    model = filters.constant_velocity(TAU, ndim=M)
    track, t = y[0], 45  # unbatched: the carry has B = 1
    candidates = {k: v[[1, 1, 0, 2]] for k, v in CONFIGS[config].items()}  # 4 sets, the first two equal
    states, carry = make(config, model, **{k: v[1] for k, v in CONFIGS[config].items()}).run_from(track[:t])
    assert states.shape == (t, 2 * M) and carry.x.shape == (1, 2 * M)
    window = np.broadcast_to(track[t:], (4, T - t, M))  # read-only, as the re-tuning env passes it
    batch, batch_carry = make(config, model, **candidates).run_from(window, carry.repeat(4))
    np.testing.assert_array_equal(batch[0], batch[1])
    for i in range(4):
        single, single_carry = make(config, model, **{k: v[i] for k, v in candidates.items()}).run_from(
            track[None, t:], carry)
        assert_same(batch[i], single[0])
        assert_same(batch_carry.P[i], single_carry.P[0])
    whole = make(config, model, **{k: v[1] for k, v in CONFIGS[config].items()}).run(track)
    assert_same(np.concatenate([states, batch[0]]), whole)


def kf_switch_reference(y: np.ndarray, t: int, before: dict, after: dict, x0: np.ndarray,
                        P0: np.ndarray) -> np.ndarray:
    """filterpy KalmanFilter (one coordinate), σ_w, σ_v of ``before`` up to frame t − 1, of ``after`` from t."""
    axis = filters.constant_velocity(TAU).axis()
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F, kf.H, kf.x, kf.P = axis.F.copy(), axis.H.copy(), x0.copy(), P0.copy()
    out = []
    for n, y_n in enumerate(y):
        p = before if n < t else after
        kf.Q, kf.R = p["sigma_w"] ** 2 * axis.B @ axis.B.T, np.eye(1) * p["sigma_v"] ** 2
        kf.predict()
        kf.update(None if np.isnan(y_n) else y_n)
        out.append(kf.x.copy())
    return np.array(out)


def cmn_switch_reference(y: np.ndarray, t: int, before: dict, after: dict, x0: np.ndarray,
                         P0: np.ndarray) -> np.ndarray:
    """filterpy time-correlated KF-CMN (as tests/filters/test_kf_cmn.py) with the parameters switched at
    frame t: from t on Q and the gap-spanning z_n = y_n − ψ^{g+1} y_m with its Γ, D, R̄, M use ``after``'s σ_w, σ_v,
    ψ (also for a z whose y_m lies before t: the frames before t were predicted with ``before``'s Q)."""
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.x, kf.P = x0.copy(), P0.copy()
    out, last = [], None
    for n in range(len(y)):
        p = before if n < t else after
        m = cmn_matrices(p["sigma_w"], p["sigma_v"], p["psi"], 0 if last is None else n - last - 1)
        kf.F, kf.Q, kf.M = m["F"], m["Q"], m["M"]
        kf.predict()
        if np.isnan(y[n]):
            kf.update(None)
        elif last is None:
            kf.update(y[n], R=np.eye(1) * p["sigma_v"] ** 2 / (1 - p["psi"] ** 2), H=m["H"])
        else:
            z = y[n] - p["psi"] ** (n - last) * y[last]
            kf.update_correlated(np.array([z]), R=m["R_bar"], H=m["D"])
        last = last if np.isnan(y[n]) else n
        out.append(kf.x.copy())
    return np.array(out)


BEFORE = {"sigma_w": 50.0, "sigma_v": 4.0, "psi": 0.6}
AFTER = {"sigma_w": 5.0, "sigma_v": 9.0, "psi": 0.9}


@pytest.mark.parametrize("t", [100, 150, 151, 201])  # y[149], y[200:202] missing: z spans the switch at 150, 201
@pytest.mark.parametrize("name", ["kf", "kf_cmn"])
def test_parameter_change_matches_switching_reference(name: str, t: int) -> None:
    y = simulate(np.random.default_rng(2), 300, 1, 50.0, 4.0)
    y[[20, 149, 200, 201]] = np.nan
    x0, P0 = np.array([100.0, 20.0]), np.diag([10.0, 100.0])
    model = filters.constant_velocity(TAU)
    keys = ("sigma_w", "sigma_v") if name == "kf" else ("sigma_w", "sigma_v", "psi")
    old = filters.make(name, model, x0=x0, P0=P0, **{k: BEFORE[k] for k in keys})
    first, carry = old.run_from(y[:t])
    second, _ = filters.make(name, model, **{k: AFTER[k] for k in keys}).run_from(y[t:], carry)
    reference = (kf_switch_reference if name == "kf" else cmn_switch_reference)(y[:, 0], t, BEFORE, AFTER, x0, P0)
    np.testing.assert_array_equal(first, old.run(y[:t]))
    assert_rel(np.concatenate([first, second]), reference, 1e-12)
    assert not np.allclose(second, old.run(y)[t:])  # the new parameters do act


def test_ukf_parameter_change_equals_kf() -> None:
    """The UKF equals the KF on the linear model, also across a carried parameter change."""
    y, _ = data(3)
    model = filters.constant_velocity(TAU, ndim=M)
    after = {"sigma_w": np.array([1.0, 100.0, 30.0]), "sigma_v": np.array([3.0, 3.0, 0.2])}
    out = {}
    for name in ("kf", "ukf"):
        first, carry = filters.make(name, model, **CONFIGS["kf"]).run_from(y[:, :50])
        out[name] = np.concatenate([first, filters.make(name, model, **after).run_from(y[:, 50:], carry)[0]], axis=1)
    assert_same(out["ukf"], out["kf"], 1e-8)


def test_carry_is_read_only_and_repeat_copies() -> None:
    _, carry = filters.make("kf", filters.constant_velocity(TAU)).run_from(np.arange(5.0)[:, None])
    with pytest.raises(ValueError, match="read-only"):
        carry.x[0, 0] = 1.0
    many = carry.repeat(3)
    assert many.x.shape == (3, 2) and many.P.shape == (3, 2, 2) and many.y_last.shape == (3, 1)
    np.testing.assert_array_equal(many.P, np.repeat(carry.P, 3, axis=0))


def test_bad_carry_is_refused() -> None:
    y, u = data()
    model = filters.constant_velocity(TAU, ndim=M)
    kf = filters.make("kf", model)
    _, carry = kf.run_from(y[:, :20])
    _, one = kf.run_from(y[0, :20])
    with pytest.raises(ValueError, match=r"carry\.x has shape \(1, 4\); allowed: \(3, 4\)"):
        kf.run_from(y[:, 20:], one)
    with pytest.raises(ValueError, match=r"carry\.x has shape"):
        filters.make("kf", filters.constant_velocity(TAU, ndim=4)).run_from(np.zeros((3, 5, 4)), carry)
    with pytest.raises(ValueError, match=r"carry\.P has shape"):
        kf.run_from(y[:, 20:], Carry(x=carry.x, P=carry.P[:, :2], y_last=carry.y_last, measured=carry.measured))
    with pytest.raises(ValueError, match=r"carry\.y_last has shape"):
        kf.run_from(y[:, 20:], Carry(x=carry.x, P=carry.P, y_last=carry.y_last[:, :1], measured=carry.measured))
    coupled = carry.P.copy()
    coupled[:, 0, 1] = coupled[:, 1, 0] = 0.1
    with pytest.raises(ValueError, match=r"carry\.P couples"):
        kf.run_from(y[:, 20:], Carry(x=carry.x, P=coupled, y_last=carry.y_last, measured=carry.measured))
    half = carry.x.copy()
    half[0, 0] = np.nan  # position NaN, velocity finite
    with pytest.raises(ValueError, match=r"carry\.x"):
        kf.run_from(y[:, 20:], Carry(x=half, P=carry.P, y_last=carry.y_last, measured=carry.measured))
    not_started = carry.x.copy()
    not_started[0] = np.nan
    with pytest.raises(ValueError, match=r"carry\.measured is True"):
        kf.run_from(y[:, 20:], Carry(x=not_started, P=carry.P, y_last=carry.y_last, measured=carry.measured))
    with pytest.raises(ValueError, match=r"carry\.x"):
        kf.run_from(y[:, 20:], Carry(x=carry.x + np.inf, P=carry.P, y_last=carry.y_last, measured=carry.measured))
    with pytest.raises(ValueError, match="carry is a dict"):
        kf.run_from(y[:, 20:], {"x": carry.x})
    camera = filters.make("ukf", model, camera_motion=True)
    _, camera_carry = camera.run_from(y[:, :20], u=u[:, :20])
    with pytest.raises(ValueError, match=r"carry\.c has shape None"):
        camera.run_from(y[:, 20:], carry)
    with pytest.raises(ValueError, match=r"carry\.c is given"):
        kf.run_from(y[:, 20:], camera_carry)
    with pytest.raises(ValueError, match=r"carry\.c and carry\.P_c"):
        Carry(x=carry.x, P=carry.P, y_last=carry.y_last, measured=carry.measured, c=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="one-track carry"):
        carry.repeat(2)
    with pytest.raises(ValueError, match="n=0"):
        one.repeat(0)


def test_a_fir_filter_refuses_a_kalman_carry_and_a_kalman_filter_a_history() -> None:
    y = np.zeros((20, 1))
    _, carry = filters.make("kf", filters.constant_velocity(TAU)).run_from(y)
    _, history = filters.make("ufir", filters.constant_velocity(TAU), horizon=10).run_from(y)
    with pytest.raises(TypeError, match="ufir: carry is a Carry; allowed: None or a bboxtune.filters.history.History"):
        filters.make("ufir", filters.constant_velocity(TAU), horizon=10).run_from(y, carry)
    with pytest.raises((TypeError, AttributeError, ValueError)):
        filters.make("kf", filters.constant_velocity(TAU)).run_from(y, history)
