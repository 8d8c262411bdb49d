"""filters.make refuses what is not a model or not a number (issue 35): a TypeError naming the argument and what is
allowed, where a str '1', a bool or None used to be coerced (or fail deep inside with an AttributeError)."""

from __future__ import annotations

import numpy as np
import pytest

from bboxtune import filters

MODEL = filters.constant_velocity(0.1, ndim=4)
VALID = {"sigma_w": 2.0, "sigma_v": 1.0}


@pytest.mark.parametrize("name", filters.NAMES + filters.PEER_NAMES)
@pytest.mark.parametrize("model", [None, "cv", 0.1, MODEL.F, {"tau": 0.1}])
def test_a_model_that_is_not_a_state_space_model_is_a_type_error_naming_it(name: str, model: object) -> None:
    with pytest.raises(TypeError, match=r"^model=.*; allowed: a StateSpaceModel, e\.g\. bboxtune\.filters\.constant_velocity"):
        filters.make(name, model)


@pytest.mark.parametrize("name", filters.NAMES)
@pytest.mark.parametrize("value", ["1", b"1", True, np.bool_(False), None, [1.0, "2"], [[1.0], [2.0, 3.0]], object(),
                                   np.array(["1"]), 1 + 0j])
def test_a_noise_scale_that_is_not_a_number_is_a_type_error_naming_it_and_its_range(name: str, value: object) -> None:
    with pytest.raises(TypeError, match=r"^sigma_w=.* is not a number; allowed: .* 1e-30 <= sigma_w <= 1e\+30$"):
        filters.make(name, MODEL, **{**VALID, "sigma_w": value})


@pytest.mark.parametrize(("name", "param", "value", "allowed"), [
    ("kf_cmn", "psi", "0.5", "0 <= psi <= 0.99"),
    ("ufir", "horizon", "20", "2 <= horizon <= 100000, an integer"),
    ("ofir", "horizon", True, "2 <= horizon <= 100000, an integer"),
    ("ukf", "alpha", None, "0.0001 <= alpha <= 10000"),
    ("bytetrack_kf", "std_weight_position", "0.05", "std_weight_position <="),
    ("kf", "x0", ["0"] * 8, "None or a finite array of shape (8,)"),
    ("kf", "P0", "eye", "None or a finite array of shape (8, 8)"),
    ("ofir", "P0", [["1", "0"], ["0", "1"]], "None or a finite symmetric positive definite (2, 2) covariance"),
])
def test_other_parameters_that_are_not_numbers(name: str, param: str, value: object, allowed: str) -> None:
    with pytest.raises(TypeError, match=rf"^{param}=.* is not a number; allowed: .*") as info:
        filters.make(name, MODEL, **{param: value})
    assert allowed in str(info.value)


def test_numbers_of_every_numeric_type_are_still_taken() -> None:
    """int, float, NumPy scalars, integer arrays and lists of numbers: the same filter as with plain floats."""
    y = np.cumsum(np.random.default_rng(0).normal(size=(2, 30, 4)), axis=1)
    expected = filters.make("kf", MODEL, sigma_w=2.0, sigma_v=1.0).run(y)
    for sigma_w, sigma_v in ((2, 1), (np.float32(2), np.int64(1)), (np.array([2, 2]), [1, 1.0]), (np.uint8(2), 1)):
        assert np.array_equal(filters.make("kf", MODEL, sigma_w=sigma_w, sigma_v=sigma_v).run(y), expected)


def test_constant_velocity_refuses_a_bool_dimension_and_a_str_interval() -> None:
    with pytest.raises(ValueError, match="ndim=True must be an integer >= 1"):
        filters.constant_velocity(0.1, ndim=True)
    with pytest.raises(TypeError, match=r"^tau='0\.1' \(str\) is not a number; allowed: .*1e-06 <= tau <= 1e\+06"):
        filters.constant_velocity("0.1")  # type: ignore[arg-type]
