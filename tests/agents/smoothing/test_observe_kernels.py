"""The compiled observation of a ``bytetrack_kf`` tuner (``bboxtune.agents.smoothing.observe_kernels``) against the
steps it replaces (``Tuner._observe_steps``): bit for bit on random tracks with missing frames, gaps, tiny boxes and
extreme sizes; where it cannot compute one, the steps run and raise their own errors."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bboxtune.agents.smoothing import observe_kernels
from bboxtune.agents.smoothing.tuner import Observation, Tuner, load_pretrained
from bboxtune.envs.data.boxes import MAX_COORD
from bboxtune.filters import jit


@st.composite
def tracks(draw: st.DrawFn) -> tuple[np.ndarray, float]:
    """A checked xywh track (at least 8 frames, 2 measured) and a frame interval in the tuner's range."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    T = draw(st.integers(8, 160))
    size = draw(st.sampled_from([1e-31, 1e-3, 40.0, 1e6]))  # 1e-31: below SIZE_MIN, no detection for the filter
    xywh = np.cumsum(rng.normal(0, draw(st.floats(0.01, 30.0)), (T, 4)), axis=0) + [320.0, 240.0, 0.0, 0.0]
    xywh[:, 2:] = size * np.exp(rng.normal(0, 0.1, (T, 2)))
    xywh[rng.random(T) < draw(st.sampled_from([0.0, 0.3, 0.7]))] = np.nan
    start = int(rng.integers(0, T))
    xywh[start:start + draw(st.integers(0, 50))] = np.nan  # a gap
    xywh[rng.choice(T, 2, replace=False)] = [100.0, 80.0, size, 2 * size]  # two measured frames at least
    return np.clip(xywh, -MAX_COORD, MAX_COORD), draw(st.floats(1e-3, 1.0))


def assert_same(got: Observation, want: Observation) -> None:
    assert got.obs.dtype == want.obs.dtype == np.float32
    np.testing.assert_array_equal(got.obs, want.obs)
    np.testing.assert_array_equal(got.y, want.y)
    assert got.nominal == want.nominal and got.tau == want.tau
    assert type(got.nominal.horizon) is int and type(got.nominal.sigma_v) is float


@pytest.fixture(scope="module")
def tuner() -> Tuner:
    return load_pretrained("mot15_det")


@settings(max_examples=80, deadline=None)
@given(tracks())
def test_the_compiled_observation_is_the_steps_bit_for_bit(track: tuple[np.ndarray, float]) -> None:
    """The same observation, or (boxes so small that the rule's σ leaves its range) the same error."""
    tuner = load_pretrained("mot15_det")
    xywh, tau = track
    assert tuner._compiled_rule is not None
    try:
        want = tuner._observe_steps(xywh, tau)
    except ValueError as err:
        with pytest.raises(ValueError, match=re.escape(str(err))):
            tuner._observe(xywh, tau)
        return
    assert_same(tuner._observe(xywh, tau), want)


def test_the_steps_run_where_the_kernel_cannot_or_may_not(tuner: Tuner, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(jit, "ENABLED", True)  # the kernels, whatever $BBOXTUNE_JIT says
    xywh = np.array([[100.0, 80.0, 30.0, 60.0]] * 10) + np.arange(10)[:, None]
    want = tuner._observe_steps(xywh, 0.04)
    calls: list[int] = []

    def steps(self: Tuner, boxes: np.ndarray, tau: float) -> Observation:
        calls.append(len(boxes))
        return want

    monkeypatch.setattr(Tuner, "_observe_steps", steps)
    assert_same(tuner._observe(xywh, 0.04), want)  # the kernel
    assert calls == []
    monkeypatch.setattr(observe_kernels, "box_observation", lambda *args: (None, None, 0.0, 0.0, 0, False))
    assert tuner._observe(xywh, 0.04) is want  # the kernel failed: the steps
    monkeypatch.setattr(jit, "ENABLED", False)
    assert tuner._observe(xywh, 0.04) is want  # the numpy references: the steps
    assert calls == [10, 10]


@pytest.mark.parametrize("name", ["otb_kf_cmn", "sim_ufir_cmn", "otb_tracker_ufir_cmn"])
def test_other_back_ends_take_the_steps(name: str) -> None:
    assert load_pretrained(name)._compiled_rule is None


def test_a_sigma_out_of_range_falls_back_to_the_steps_error(tuner: Tuner) -> None:
    """Boxes of 1e-31 px (a rule σ_v of 3e-33 px, below SIGMA_RANGE): the kernel reports it invalid, the steps raise
    their error naming σ_v."""
    xywh = np.array([[100.0, 80.0, 1e-31, 1e-31]] * 10) + np.arange(10)[:, None] * [1, 1, 0, 0]
    with pytest.raises(ValueError, match="sigma_v=.* is out of range"):
        tuner._observe(xywh, 0.04)
